# Cross-compiling for arm64 (aarch64) on Debian with crossbuild-essential-arm64. The arm64
# libraries the build needs (yaml-cpp, GoogleTest) come from a sysroot folder holding the arm64
# Debian packages unpacked with dpkg-deb -x (POISE_ARM64_SYSROOT; tools/cross_arm64.sh makes it),
# never from arm64 -dev packages installed system-wide (libyaml-cpp-dev is not Multi-Arch: same,
# installing its arm64 package removes the amd64 one). Eigen is header-only (the host's).
# Executables (tests, gtest_discover_tests) run under qemu-user-static with the cross C library.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES POISE_ARM64_SYSROOT)
if(NOT POISE_ARM64_SYSROOT)
  message(FATAL_ERROR "set POISE_ARM64_SYSROOT to the unpacked arm64 packages (tools/cross_arm64.sh)")
endif()
# Packages are looked for in the sysroot first, then on the host (Eigen's arch-independent config).
set(CMAKE_FIND_ROOT_PATH ${POISE_ARM64_SYSROOT} /)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)
find_program(POISE_QEMU_AARCH64 NAMES qemu-aarch64-static qemu-aarch64 REQUIRED)
# -L: the arm64 loader and C/C++ runtime of the cross toolchain; the sysroot's libraries are found
# through the executables' build RPATH.
set(CMAKE_CROSSCOMPILING_EMULATOR ${POISE_QEMU_AARCH64} -L /usr/aarch64-linux-gnu)
