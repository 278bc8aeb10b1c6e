# Shared CMake helpers for poise targets.

# Add every immediate subdirectory of DIR that contains a CMakeLists.txt (sorted, deterministic).
# A subdirectory without one that only groups folders (components/estimators/, components/bridges/)
# is descended into, one level.
function(poise_add_subdirectories dir)
  file(GLOB children LIST_DIRECTORIES true RELATIVE ${CMAKE_CURRENT_SOURCE_DIR}/${dir}
       ${CMAKE_CURRENT_SOURCE_DIR}/${dir}/*)
  list(SORT children)
  foreach(child IN LISTS children)
    set(path ${CMAKE_CURRENT_SOURCE_DIR}/${dir}/${child})
    if(EXISTS ${path}/CMakeLists.txt)
      add_subdirectory(${dir}/${child})
    elseif(IS_DIRECTORY ${path} AND NOT child STREQUAL "include" AND NOT child STREQUAL "src")
      file(GLOB grandchildren LIST_DIRECTORIES true RELATIVE ${path} ${path}/*)
      list(SORT grandchildren)
      foreach(grandchild IN LISTS grandchildren)
        if(EXISTS ${path}/${grandchild}/CMakeLists.txt)
          add_subdirectory(${dir}/${child}/${grandchild})
        endif()
      endforeach()
    endif()
  endforeach()
endfunction()

# Warnings (as errors with POISE_WERROR) on poise's own targets only; never on generated code.
function(poise_target_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow=local
                         -Wnon-virtual-dtor -Wold-style-cast -Wcast-align -Wunused
                         -Woverloaded-virtual -Wnull-dereference -Wdouble-promotion
                         -Wformat=2 -Wimplicit-fallthrough)
  if(POISE_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

# poise_add_library(NAME [STATIC] SOURCES ... [DEPS ...] [PRIVATE_DEPS ...])
# A library with include/ as its public include dir and poise's warnings.
function(poise_add_library name)
  cmake_parse_arguments(A "" "" "SOURCES;DEPS;PRIVATE_DEPS" ${ARGN})
  if(A_SOURCES)
    add_library(${name} STATIC ${A_SOURCES})
    target_include_directories(${name} PUBLIC $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
                                              $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
    target_link_libraries(${name} PUBLIC ${A_DEPS} PRIVATE ${A_PRIVATE_DEPS})
    poise_target_warnings(${name})
  else()
    add_library(${name} INTERFACE)
    target_include_directories(${name} INTERFACE $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
                                                 $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
    target_link_libraries(${name} INTERFACE ${A_DEPS})
  endif()
endfunction()

# poise_add_test(NAME SOURCES ... [DEPS ...] [LABELS ...] [TIMEOUT s] [SERIAL])
# A GoogleTest executable; each TEST() becomes one ctest entry. Every test gets a timeout.
# SERIAL marks tests that must not run in parallel with others (e.g. network namespaces).
function(poise_add_test name)
  cmake_parse_arguments(A "SERIAL" "TIMEOUT" "SOURCES;DEPS;LABELS" ${ARGN})
  if(NOT A_TIMEOUT)
    set(A_TIMEOUT 120)
  endif()
  add_executable(${name} ${A_SOURCES})
  target_link_libraries(${name} PRIVATE ${A_DEPS} poise_testing GTest::gtest GTest::gmock GTest::gtest_main)
  poise_target_warnings(${name})
  # The test's own code at -O1: the code under test is the libraries', built as configured (-O3 in
  # Release). Test sources are half of a cold build's compile time, and -O1 takes a quarter off
  # each (selective_ekf_test.cpp: 32 -> 24 s); -O0 is no faster with Eigen (31.6 s).
  target_compile_options(${name} PRIVATE $<$<CONFIG:Release>:-O1>)
  set(props TIMEOUT ${A_TIMEOUT} ENVIRONMENT "POISE_DDS_PROFILE=poise_loopback;POISE_SHARED_DIR=${POISE_SHARED_DIR};POISE_SOURCE_DIR=${PROJECT_SOURCE_DIR};POISE_BINARY_DIR=${PROJECT_BINARY_DIR}")
  if(A_LABELS)
    list(APPEND props LABELS "${A_LABELS}")
  endif()
  if(A_SERIAL)
    list(APPEND props RUN_SERIAL TRUE)
  endif()
  gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES ${props})
endfunction()

# poise_add_cli_module(TARGET FUNCTION)
# Registers `void FUNCTION(CLI::App& app)` from library TARGET as a provider of `poise` subcommands.
# The function must be declared in namespace poise::cli.
function(poise_add_cli_module target fn)
  set_property(GLOBAL APPEND PROPERTY POISE_CLI_TARGETS ${target})
  set_property(GLOBAL APPEND PROPERTY POISE_CLI_FUNCTIONS ${fn})
endfunction()

# poise_add_component_module(TARGET FUNCTION)
# Library TARGET provides `void poise::runtime::FUNCTION(poise::runtime::ComponentRegistry&)`,
# which registers component types (for `poise run` host files and `poise <component>`).
function(poise_add_component_module target fn)
  set_property(GLOBAL APPEND PROPERTY POISE_COMPONENT_TARGETS ${target})
  set_property(GLOBAL APPEND PROPERTY POISE_COMPONENT_FUNCTIONS ${fn})
endfunction()

# Generates the module table and builds the `poise` executable (called once, at the end).
function(poise_finalize_cli)
  get_property(targets GLOBAL PROPERTY POISE_CLI_TARGETS)
  get_property(fns GLOBAL PROPERTY POISE_CLI_FUNCTIONS)
  get_property(ctargets GLOBAL PROPERTY POISE_COMPONENT_TARGETS)
  get_property(cfns GLOBAL PROPERTY POISE_COMPONENT_FUNCTIONS)
  set(cdecls "")
  set(ccalls "")
  foreach(fn IN LISTS cfns)
    string(APPEND cdecls "void ${fn}(ComponentRegistry& registry);\n")
    string(APPEND ccalls "  ${fn}(registry);\n")
  endforeach()
  set(decls "")
  set(calls "")
  foreach(fn IN LISTS fns)
    string(APPEND decls "void ${fn}(CLI::App& app);\n")
    string(APPEND calls "  ${fn}(app);\n")
  endforeach()
  set(out ${PROJECT_BINARY_DIR}/generated/cli_modules.cpp)
  file(CONFIGURE OUTPUT ${out} CONTENT
"// Generated by poise_finalize_cli(): registers every component and CLI module. Do not edit.
#include <CLI/CLI.hpp>
#include \"poise/runtime/component.h\"
namespace poise::runtime {
${cdecls}
void register_all_components() {
  [[maybe_unused]] ComponentRegistry& registry = ComponentRegistry::instance();
${ccalls}}
}  // namespace poise::runtime
namespace poise::cli {
${decls}
void register_all_modules([[maybe_unused]] CLI::App& app) {
${calls}}
}  // namespace poise::cli
")
  add_executable(poise ${PROJECT_SOURCE_DIR}/tools/poise/cli/src/main.cpp ${out})
  target_link_libraries(poise PRIVATE poise_cli_common poise_runtime ${targets} ${ctargets})
  poise_target_warnings(poise)
  set_target_properties(poise PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)
endfunction()
