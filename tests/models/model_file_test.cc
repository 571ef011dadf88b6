// Model files: round trip, and rejection of bad files with one-line errors.
#include "diffdyn/models/model_file.h"

#include <filesystem>
#include <fstream>
#include <string>

#include <unistd.h>

#include <gtest/gtest.h>

#include "diffdyn/models/init.h"

namespace diffdyn {
namespace {

namespace fs = std::filesystem;

// One folder per process: ctest runs every test as its own process, in parallel.
fs::path TempDir() {
  const fs::path dir = fs::path(DIFFDYN_BINARY_DIR) / "test_tmp" /
                       ("models_" + std::to_string(getpid()));
  fs::create_directories(dir);
  return dir;
}

Mlp<double> Net() {
  return MakeInitializedMlp({{2, 5, 4, 3}, {Activation::Softplus(2.0), Activation::Elu(0.5)}},
                            InitOptions{}, 7);
}

std::string ReadModelText(const fs::path& p) {
  std::ifstream in(p);
  return {std::istreambuf_iterator<char>(in), {}};
}

void WriteAll(const fs::path& p, const std::string& s) { std::ofstream(p) << s; }

// Expects LoadMlp(path) to throw one line naming the file and containing `needle`.
void ExpectRejected(const fs::path& path, const std::string& needle) {
  try {
    LoadMlp(path);
    ADD_FAILURE() << "accepted " << path;
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}

TEST(ModelFile, RoundTripIsBitExact) {
  const fs::path path = TempDir() / "roundtrip.json";
  const Mlp<double> net = Net();
  SaveMlp(path, net, {{"seed", 7}, {"data", "none"}}, {{"val_loss", 0.125}});
  ModelFile contents;
  const Mlp<double> back = LoadMlp(path, &contents);
  EXPECT_EQ(back.architecture(), net.architecture());
  EXPECT_TRUE(back.parameters() == net.parameters());
  EXPECT_EQ(contents.provenance["seed"], 7);
  EXPECT_EQ(contents.metrics["val_loss"], 0.125);
  const nlohmann::json j = nlohmann::json::parse(ReadModelText(path));
  EXPECT_EQ(j["format"], "diffdyn-model");
  EXPECT_EQ(j["version"], kModelFileVersion);
  EXPECT_EQ(j["kind"], "mlp");
  // No temporary file left behind.
  EXPECT_FALSE(fs::exists(TempDir() / ".roundtrip.json.tmp"));
}

TEST(ModelFile, RejectsTruncatedFiles) {
  const fs::path good = TempDir() / "good.json";
  SaveMlp(good, Net());
  const std::string text = ReadModelText(good);
  for (double fraction : {0.0, 0.3, 0.9}) {
    const fs::path bad = TempDir() / "truncated.json";
    WriteAll(bad, text.substr(0, static_cast<std::size_t>(fraction * text.size())));
    ExpectRejected(bad, "not valid JSON");
  }
  ExpectRejected(TempDir() / "does_not_exist.json", "no such file");
}

// Writes a modified copy of a good file.
fs::path Modified(const std::string& name, const std::function<void(nlohmann::json&)>& edit) {
  const fs::path good = TempDir() / "good2.json";
  SaveMlp(good, Net());
  nlohmann::json j = nlohmann::json::parse(ReadModelText(good));
  edit(j);
  const fs::path path = TempDir() / name;
  WriteAll(path, j.dump());
  return path;
}

TEST(ModelFile, RejectsWrongFormatVersionAndKind) {
  ExpectRejected(Modified("v2.json", [](auto& j) { j["version"] = 2; }), "version 2");
  ExpectRejected(Modified("nov.json", [](auto& j) { j.erase("version"); }), "version");
  ExpectRejected(Modified("fmt.json", [](auto& j) { j["format"] = "other"; }), "diffdyn-model");
  ExpectRejected(Modified("kind.json", [](auto& j) { j["kind"] = "mystery"; }), "unknown model kind");
  ExpectRejected(Modified("noprov.json", [](auto& j) { j.erase("provenance"); }), "provenance");
  ExpectRejected(Modified("act.json",
                          [](auto& j) { j["architecture"]["activations"][0]["name"] = "swish"; }),
                 "swish");
}

TEST(ModelFile, RejectsWrongSizes) {
  // One value fewer, count unchanged.
  ExpectRejected(Modified("short.json", [](auto& j) { j["parameters"]["values"].erase(0); }),
                 "'count' says");
  // One value fewer and a matching count: the architecture disagrees.
  ExpectRejected(Modified("short2.json",
                          [](auto& j) {
                            j["parameters"]["values"].erase(0);
                            j["parameters"]["count"] = j["parameters"]["values"].size();
                          }),
                 "parameters, the file has");
  ExpectRejected(Modified("arch.json", [](auto& j) { j["architecture"]["sizes"][1] = 6; }),
                 "parameters, the file has");
  ExpectRejected(Modified("acts.json",
                          [](auto& j) { j["architecture"]["activations"].erase(0); }),
                 "hidden layers");
}

TEST(ModelFile, RejectsNonFiniteParameters) {
  ExpectRejected(Modified("null.json", [](auto& j) { j["parameters"]["values"][3] = nullptr; }),
                 "parameter 3 is not a finite number");
  ExpectRejected(Modified("str.json", [](auto& j) { j["parameters"]["values"][0] = "1.0"; }),
                 "parameter 0");
  // A literal too large for a double.
  const fs::path good = TempDir() / "good3.json";
  SaveMlp(good, Net());
  std::string text = ReadModelText(good);
  const std::size_t at = text.find("\"values\"");
  const std::size_t first = text.find_first_of("-0123456789", at);
  const std::size_t end = text.find_first_of(",\n]", first);
  text.replace(first, end - first, "1e999");
  const fs::path big = TempDir() / "inf.json";
  WriteAll(big, text);
  ExpectRejected(big, "");
  // Saving a non-finite model is refused and leaves the old file intact.
  Mlp<double> nan_net = Net();
  nan_net.mutable_parameters()[1] = std::nan("");
  const std::string before = ReadModelText(good);
  EXPECT_THROW(SaveMlp(good, nan_net), Error);
  EXPECT_EQ(ReadModelText(good), before);
}

TEST(ModelFile, OtherKindsRegisterThroughTheSameLoader) {
  RegisterModelKind("test-affine", [](const nlohmann::json& a) -> Eigen::Index {
    DIFFDYN_CHECK(a.contains("n") && a["n"].is_number_integer(), "needs integer 'n'");
    return a["n"].get<int>() + 1;
  });
  EXPECT_TRUE(IsModelKindRegistered("test-affine"));
  const fs::path path = TempDir() / "affine.json";
  SaveModelFile(path, {"test-affine", {{"n", 2}}, Eigen::Vector3d(1, 2, 3), {}, {}});
  const ModelFile file = LoadModelFile(path);
  EXPECT_EQ(file.kind, "test-affine");
  EXPECT_EQ(file.parameters, Eigen::Vector3d(1, 2, 3));
  EXPECT_THROW(SaveModelFile(path, {"test-affine", {{"n", 5}}, Eigen::Vector3d(1, 2, 3), {}, {}}), Error);
  ExpectRejected(path, "expected 'mlp'");
}

}  // namespace
}  // namespace diffdyn
