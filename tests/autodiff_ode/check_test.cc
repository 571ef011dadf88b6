// The error type and check macro of the core (check.h).
#include "diffdyn/autodiff_ode/check.h"

#include <gtest/gtest.h>

namespace diffdyn {
namespace {

TEST(Check, ThrowsErrorWithAllMessageParts) {
  try {
    DIFFDYN_CHECK(1 + 1 == 3, "state has ", 4, " entries, the system expects ", 2.5);
    FAIL() << "no exception";
  } catch (const Error& e) {
    EXPECT_STREQ(e.what(), "state has 4 entries, the system expects 2.5");
  }
  EXPECT_NO_THROW(DIFFDYN_CHECK(true, "never"));
}

}  // namespace
}  // namespace diffdyn
