#include "poise/eval/broad.h"

#include "poise/core/attitude.h"

#include <hdf5.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

namespace poise::eval {
namespace {

// RAII for HDF5 ids.
class H5Id {
 public:
  H5Id(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~H5Id() {
    if (id_ >= 0) {
      close_(id_);
    }
  }
  H5Id(const H5Id&) = delete;
  H5Id& operator=(const H5Id&) = delete;
  [[nodiscard]] hid_t get() const { return id_; }
  [[nodiscard]] bool ok() const { return id_ >= 0; }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

struct Array2 {
  size_t rows = 0;  // samples
  size_t cols = 0;  // components
  std::vector<double> data;  // row-major rows x cols
};

// Reads a 1-D or 2-D numeric dataset as doubles, oriented samples x components where the
// component count is `cols` (a k x N dataset is transposed).
Array2 read_matrix(hid_t file, const std::string& name, size_t cols, const std::string& path) {
  H5Id ds(H5Dopen2(file, name.c_str(), H5P_DEFAULT), H5Dclose);
  if (!ds.ok()) {
    throw std::runtime_error(path + ": dataset '" + name + "' not found (is this a BROAD file?)");
  }
  H5Id space(H5Dget_space(ds.get()), H5Sclose);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank < 1 || rank > 2) {
    throw std::runtime_error(path + ": dataset '" + name + "' has rank " + std::to_string(rank));
  }
  hsize_t dims[2] = {0, 1};
  H5Sget_simple_extent_dims(space.get(), dims, nullptr);
  const size_t d0 = static_cast<size_t>(dims[0]);
  const size_t d1 = rank == 2 ? static_cast<size_t>(dims[1]) : 1;
  const size_t total = d0 * d1;
  std::vector<double> raw(total);
  H5Id ftype(H5Dget_type(ds.get()), H5Tclose);
  if (H5Tget_class(ftype.get()) == H5T_ENUM || H5Tget_class(ftype.get()) == H5T_INTEGER) {
    // bool stored as an enum (h5py) or as integers: read the raw integer values.
    H5Id base(H5Tget_class(ftype.get()) == H5T_ENUM ? H5Tget_super(ftype.get()) : H5Tcopy(ftype.get()),
              H5Tclose);
    H5Id native(H5Tget_native_type(ftype.get(), H5T_DIR_ASCEND), H5Tclose);
    const size_t sz = H5Tget_size(native.get());
    const bool is_signed = H5Tget_sign(base.get()) == H5T_SGN_2;
    std::vector<unsigned char> buf(total * sz);
    if (H5Dread(ds.get(), native.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, buf.data()) < 0) {
      throw std::runtime_error(path + ": cannot read dataset '" + name + "'");
    }
    for (size_t i = 0; i < total; ++i) {
      int64_t v = 0;
      const unsigned char* p = &buf[i * sz];
      switch (sz) {
        case 1: v = is_signed ? static_cast<int64_t>(static_cast<int8_t>(p[0])) : p[0]; break;
        case 2: { int16_t t; std::memcpy(&t, p, 2); v = is_signed ? t : static_cast<uint16_t>(t); break; }
        case 4: { int32_t t; std::memcpy(&t, p, 4); v = is_signed ? t : static_cast<uint32_t>(t); break; }
        default: { int64_t t; std::memcpy(&t, p, 8); v = t; break; }
      }
      raw[i] = static_cast<double>(v);
    }
  } else {
    if (H5Dread(ds.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, raw.data()) < 0) {
      throw std::runtime_error(path + ": cannot read dataset '" + name + "' as numbers");
    }
  }
  Array2 out;
  out.cols = cols;
  if (d1 == cols) {
    out.rows = d0;
    out.data = std::move(raw);
  } else if (d0 == cols) {
    out.rows = d1;
    out.data.resize(total);
    for (size_t r = 0; r < d1; ++r) {
      for (size_t c = 0; c < cols; ++c) {
        out.data[r * cols + c] = raw[c * d1 + r];
      }
    }
  } else {
    throw std::runtime_error(path + ": dataset '" + name + "' has shape " + std::to_string(d0) + " x " +
                             std::to_string(d1) + ", expected N x " + std::to_string(cols));
  }
  return out;
}

double read_rate(hid_t file, const std::string& path) {
  if (H5Aexists(file, "sampling_rate") <= 0) {
    throw std::runtime_error(path + ": attribute 'sampling_rate' not found");
  }
  H5Id attr(H5Aopen(file, "sampling_rate", H5P_DEFAULT), H5Aclose);
  H5Id space(H5Aget_space(attr.get()), H5Sclose);
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n < 1) {
    throw std::runtime_error(path + ": attribute 'sampling_rate' is empty");
  }
  std::vector<double> v(static_cast<size_t>(n));
  if (H5Aread(attr.get(), H5T_NATIVE_DOUBLE, v.data()) < 0) {
    throw std::runtime_error(path + ": cannot read attribute 'sampling_rate'");
  }
  return v[0];
}

std::vector<Eigen::Vector3d> to_vec3(const Array2& a) {
  std::vector<Eigen::Vector3d> out(a.rows);
  for (size_t i = 0; i < a.rows; ++i) {
    out[i] = Eigen::Vector3d(a.data[3 * i], a.data[3 * i + 1], a.data[3 * i + 2]);
  }
  return out;
}

}  // namespace

void check_rate(double rate_hz, const std::string& what) {
  if (!(rate_hz >= kBroadMinRateHz && rate_hz <= kBroadMaxRateHz)) {  // NaN fails too
    std::ostringstream os;
    os << what << " = " << rate_hz << " Hz is not a sampling rate (must be finite, between " << kBroadMinRateHz
       << " and " << kBroadMaxRateHz << " Hz)";
    throw std::runtime_error(os.str());
  }
}

int trial_number_from_stem(const std::string& stem) {
  int n = 0;
  size_t i = 0;
  while (i < stem.size() && stem[i] >= '0' && stem[i] <= '9') {
    n = n * 10 + (stem[i] - '0');
    ++i;
  }
  return i == 0 ? 0 : n;
}

ImuSample BroadTrial::sample(size_t k) const {
  ImuSample s;
  s.stamp_ns = static_cast<int64_t>(std::llround(static_cast<double>(k) * 1e9 / rate_hz));
  s.seq = static_cast<uint32_t>(k);
  s.gyro_rps = gyr_rps[k];
  s.accel_mps2 = acc_mps2[k];
  s.mag_ut = mag_ut[k];
  s.has_mag = true;  // imu_mag is part of the layout
  return s;
}

BroadTrial load_broad(const std::string& path) {
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // errors are reported by exceptions
  H5Id file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.ok()) {
    throw std::runtime_error("cannot open HDF5 file '" + path + "' (missing or not HDF5)");
  }
  BroadTrial t;
  t.path = path;
  const size_t slash = path.find_last_of('/');
  std::string base = slash == std::string::npos ? path : path.substr(slash + 1);
  const size_t dot = base.find_last_of('.');
  t.stem = dot == std::string::npos ? base : base.substr(0, dot);
  t.number = trial_number_from_stem(t.stem);
  t.rate_hz = read_rate(file.get(), path);
  check_rate(t.rate_hz, path + ": attribute 'sampling_rate'");
  t.gyr_rps = to_vec3(read_matrix(file.get(), "imu_gyr", 3, path));
  t.acc_mps2 = to_vec3(read_matrix(file.get(), "imu_acc", 3, path));
  t.mag_ut = to_vec3(read_matrix(file.get(), "imu_mag", 3, path));
  const Array2 q = read_matrix(file.get(), "opt_quat", 4, path);
  t.opt_quat_wxyz.resize(q.rows);
  for (size_t i = 0; i < q.rows; ++i) {
    t.opt_quat_wxyz[i] = Eigen::Vector4d(q.data[4 * i], q.data[4 * i + 1], q.data[4 * i + 2], q.data[4 * i + 3]);
    if (t.opt_quat_wxyz[i].allFinite() && !(std::abs(t.opt_quat_wxyz[i].norm() - 1.0) <= kReferenceNormTol)) {
      t.opt_quat_wxyz[i].setConstant(std::numeric_limits<double>::quiet_NaN());
      ++t.invalid_reference_rows;
    }
  }
  const Array2 mv = read_matrix(file.get(), "movement", 1, path);
  t.movement.resize(mv.rows);
  for (size_t i = 0; i < mv.rows; ++i) {
    t.movement[i] = mv.data[i] != 0.0 ? 1 : 0;
  }
  if (H5Lexists(file.get(), "opt_pos", H5P_DEFAULT) > 0) {
    t.opt_pos_m = to_vec3(read_matrix(file.get(), "opt_pos", 3, path));
  }
  const size_t n = t.gyr_rps.size();
  if (!t.opt_pos_m.empty() && t.opt_pos_m.size() != n) {
    throw std::runtime_error(path + ": opt_pos has a different length");
  }
  if (t.acc_mps2.size() != n || t.mag_ut.size() != n || t.opt_quat_wxyz.size() != n || t.movement.size() != n) {
    throw std::runtime_error(path + ": datasets have different lengths");
  }
  return t;
}

Eigen::Vector3d broad_sample_errors_deg(const Eigen::Quaterniond& q_est, const Eigen::Quaterniond& q_ref) {
  const Eigen::Quaterniond e = q_est.normalized() * q_ref.normalized().conjugate();
  const double w = std::abs(e.w());
  const double total = 2.0 * std::acos(std::min(1.0, w));
  const HeadingInclination hi = heading_inclination_of_world_error(e);
  return Eigen::Vector3d(total, hi.heading_rad, hi.inclination_rad) * kDegPerRad;
}

TrialErrors broad_errors(const std::vector<Eigen::Quaterniond>& estimates, const BroadTrial& trial) {
  if (estimates.size() != trial.size()) {
    throw std::invalid_argument("broad_errors: one estimate per sample is required");
  }
  Eigen::Vector3d sq = Eigen::Vector3d::Zero();
  size_t n = 0;
  size_t nonfinite = 0;
  for (size_t k = 0; k < trial.size(); ++k) {
    if (trial.movement[k] == 0 || !trial.opt_quat_wxyz[k].allFinite()) {
      continue;
    }
    Eigen::Vector3d e = Eigen::Vector3d::Constant(180.0);
    const double norm = estimates[k].coeffs().norm();
    if (std::isfinite(norm) && norm > 0.0) {
      e = broad_sample_errors_deg(estimates[k], quat_from_wxyz(trial.opt_quat_wxyz[k]));
    } else {
      ++nonfinite;
    }
    sq += e.cwiseProduct(e);
    ++n;
  }
  TrialErrors out;
  out.samples = n;
  out.nonfinite_estimates = nonfinite;
  if (n > 0) {
    const Eigen::Vector3d rms = (sq / static_cast<double>(n)).cwiseSqrt();
    out.total_deg = rms.x();
    out.heading_deg = rms.y();
    out.inclination_deg = rms.z();
  }
  return out;
}

}  // namespace poise::eval
