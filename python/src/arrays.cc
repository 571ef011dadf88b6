#include "arrays.h"

#include <cmath>
#include <string>
#include <vector>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn::python {

std::atomic<long>& InputCopies() {
  static std::atomic<long> copies{0};
  return copies;
}

py::array_t<double> ReadArray(const py::handle& object, int ndim, const std::string& what) {
  py::array in = py::array::ensure(object);
  if (!in) throw py::value_error(what + ": expected a numpy array (or a nested list of numbers)");
  if (in.ndim() != ndim) {
    throw py::value_error(StrCat(what, ": expected ", ndim, " dimensions, got ", in.ndim()));
  }
  const char kind = in.dtype().kind();
  if (kind != 'f' && kind != 'i' && kind != 'u') {
    throw py::value_error(StrCat(what, ": expected numbers, got an array of dtype kind '", kind, "'"));
  }
  py::array_t<double> out;
  if (in.dtype().is(py::dtype::of<double>()) && (in.flags() & py::array::c_style) != 0) {
    out = py::reinterpret_borrow<py::array_t<double>>(in);
  } else {
    out = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(in);
    if (!out) throw py::value_error(what + ": cannot be converted to float64");
    ++InputCopies();
  }
  const double* data = out.data();
  for (py::ssize_t i = 0; i < out.size(); ++i) {
    if (!std::isfinite(data[i])) {
      throw py::value_error(StrCat(what, ": entry ", i, " (in C order) is not finite"));
    }
  }
  return out;
}

Batch ReadBatch(const py::handle& object, int size, const std::string& what) {
  py::array in = py::array::ensure(object);
  if (!in) throw py::value_error(what + ": expected a numpy array (or a nested list of numbers)");
  if (in.ndim() != 1 && in.ndim() != 2) {
    throw py::value_error(StrCat(what, ": expected shape (", size, ",) or (N, ", size, "), got ", in.ndim(),
                                 " dimensions"));
  }
  Batch batch;
  batch.single = in.ndim() == 1;
  batch.float32 = in.dtype().is(py::dtype::of<float>());
  batch.samples = batch.single ? 1 : static_cast<int>(in.shape(0));
  batch.size = static_cast<int>(in.shape(in.ndim() - 1));
  if (batch.size != size || batch.samples < 1) {
    throw py::value_error(StrCat(what, ": expected shape (", size, ",) or (N, ", size, ") with N >= 1, got (",
                                 batch.single ? "" : StrCat(in.shape(0), ", "), in.shape(in.ndim() - 1),
                                 batch.single ? ",)" : ")"));
  }
  batch.array = ReadArray(in, static_cast<int>(in.ndim()), what);
  return batch;
}

py::array_t<double> NewArray(const std::vector<py::ssize_t>& shape) { return py::array_t<double>(shape); }

py::array_t<double> FromColumns(const Eigen::Ref<const Eigen::MatrixXd>& columns) {
  py::array_t<double> out = NewArray({columns.cols(), columns.rows()});
  Eigen::Map<Eigen::MatrixXd>(out.mutable_data(), columns.rows(), columns.cols()) = columns;
  return out;
}

py::array_t<double> FromVector(const Eigen::Ref<const Eigen::VectorXd>& v) {
  py::array_t<double> out = NewArray({v.size()});
  Eigen::Map<Eigen::VectorXd>(out.mutable_data(), v.size()) = v;
  return out;
}

py::array Returned(const py::array_t<double>& result, bool float32) {
  if (!float32) return result;
  return py::array_t<float>(result);  // converting copy
}

void CheckFiniteResult(const py::array_t<double>& result, const std::string& what) {
  const double* data = result.data();
  for (py::ssize_t i = 0; i < result.size(); ++i) {
    if (!std::isfinite(data[i])) {
      throw NumericalError(StrCat(what, ": the result is not finite (entry ", i, " in C order)"));
    }
  }
}

}  // namespace diffdyn::python
