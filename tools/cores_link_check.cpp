// Steps every estimator core once, so the link pulls in their code (tools/check_cores.sh, -DPOISE_CORES_ONLY=ON).
#include "poise/altitude/altitude_filter.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/parallel_kf/parallel_kf.h"
#include "poise/selective_ekf/selective_ekf.h"
#include "poise/vehicle/vehicle_estimator.h"

int main() {
  poise::ImuSample s;
  s.accel_mps2 = Eigen::Vector3d(0, 0, 9.81);
  s.mag_ut = Eigen::Vector3d(0, 20, -40);
  s.has_mag = true;
  poise::ParallelKf pkf;
  poise::GaussNewton gn;
  poise::SelectiveEkf sekf;
  poise::AltitudeFilter alt;
  poise::VehicleEstimator veh;
  bool ok = pkf.update(s) && gn.update(s) && sekf.update_imu(s);
  alt.update(s);
  ok = veh.update(poise::vehicle_sample_from_imu(s, true, 0.0)) && ok;
  sekf.update_vision(poise::to_vision_pose(poise::CameraPoseMeasurement{}));
  return ok && !pkf.sources().empty() && !poise::selective_ekf_sources(sekf).empty() ? 0 : 1;
}
