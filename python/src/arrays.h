// numpy batches as the library's column-major matrices.
//
// The library takes a batch of N samples of size n as a column-major n x N matrix
// (one sample per column). A C-contiguous numpy array of shape (N, n) holds, byte
// for byte, that matrix, so a float64 C-contiguous batch is read in place (a view,
// no copy); any other array (float32, integers, Fortran order, a strided slice) is
// converted once to a float64 C-contiguous copy, and InputCopies() counts those
// conversions (the tests check the zero-copy path with it). Results are written
// straight into freshly made C-contiguous numpy arrays.
#pragma once

#include <atomic>
#include <string>

#include <Eigen/Core>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

namespace diffdyn::python {

namespace py = pybind11;

/// Conversions (copies) of input arrays since the module was loaded.
std::atomic<long>& InputCopies();

/// A batch of samples of one size, read in place where the layout allows.
struct Batch {
  /// The float64 C-contiguous data (the caller's array, or its converted copy).
  py::array_t<double> array;
  /// N, the number of samples, and the sample size n.
  int samples = 0;
  int size = 0;
  /// Whether the input was one sample (a 1-D array) rather than a batch (2-D).
  bool single = false;
  /// Whether the input was float32 (results are then returned as float32).
  bool float32 = false;

  /// The n x N column-major view of the data.
  Eigen::Map<const Eigen::MatrixXd> matrix() const {
    return {array.data(), Eigen::Index(size), Eigen::Index(samples)};
  }
};

/// `object` as samples of `size` entries: shape (size,) or (N, size) with N >= 1,
/// finite. Throws py::value_error naming `what` (e.g. "predict: x") otherwise.
Batch ReadBatch(const py::handle& object, int size, const std::string& what);

/// `object` as a float64 C-contiguous array of exactly `ndim` dimensions, finite;
/// converted (and counted) when it is not one. Throws py::value_error naming `what`.
py::array_t<double> ReadArray(const py::handle& object, int ndim, const std::string& what);

/// A new C-contiguous float64 array of the given shape.
py::array_t<double> NewArray(const std::vector<py::ssize_t>& shape);

/// A new (N, rows) array holding the columns of a rows x N matrix, one per row.
py::array_t<double> FromColumns(const Eigen::Ref<const Eigen::MatrixXd>& columns);

/// A new 1-D array holding `v`.
py::array_t<double> FromVector(const Eigen::Ref<const Eigen::VectorXd>& v);

/// `result` as float32 when `float32`, else itself.
py::array Returned(const py::array_t<double>& result, bool float32);

/// Throws diffdyn::NumericalError naming `what` when `result` holds a non-finite value.
void CheckFiniteResult(const py::array_t<double>& result, const std::string& what);

}  // namespace diffdyn::python
