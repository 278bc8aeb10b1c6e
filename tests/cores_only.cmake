# The estimator cores' unit tests in a cores-only build (-DPOISE_CORES_ONLY=ON
# -DPOISE_CORES_TESTS=ON): the test files that need nothing but the cores, the sensor simulator
# (poise_sim, pure C++/Eigen) and GoogleTest. What tools/cross_arm64.sh builds for arm64 and runs
# under qemu-user. Left out (they need the evaluation harness, HDF5 or the CLI):
# selective_ekf/selective_ekf_test.cpp, altitude/altitude_sim_test.cpp, vehicle/vehicle_sim_test.cpp
# and the *_cli_test.cpp files.
enable_testing()
find_package(GTest REQUIRED)
include(GoogleTest)
add_subdirectory(${PROJECT_SOURCE_DIR}/components/sim ${PROJECT_BINARY_DIR}/components/sim)
add_subdirectory(${PROJECT_SOURCE_DIR}/tests/support ${PROJECT_BINARY_DIR}/tests/support)
set(t ${PROJECT_SOURCE_DIR}/tests)
poise_add_test(poise_core_attitude_test SOURCES ${t}/core/attitude_test.cpp DEPS poise_core TIMEOUT 120)
poise_add_test(poise_parallel_kf_test
  SOURCES ${t}/parallel_kf/tilt_kf_test.cpp ${t}/parallel_kf/parallel_kf_test.cpp
          ${t}/parallel_kf/parallel_kf_report_test.cpp
  DEPS poise_parallel_kf poise_sim TIMEOUT 120)
poise_add_test(poise_gauss_newton_test SOURCES ${t}/gauss_newton/gauss_newton_test.cpp
  DEPS poise_gauss_newton poise_sim TIMEOUT 120)
poise_add_test(poise_selective_ekf_report_test SOURCES ${t}/selective_ekf/selective_ekf_report_test.cpp
  DEPS poise_selective_ekf TIMEOUT 120)
poise_add_test(poise_altitude_test SOURCES ${t}/altitude/baro_test.cpp ${t}/altitude/altitude_filter_test.cpp
  DEPS poise_altitude TIMEOUT 120)
poise_add_test(poise_vehicle_test SOURCES ${t}/vehicle/vehicle_estimator_test.cpp
  DEPS poise_vehicle TIMEOUT 120)
