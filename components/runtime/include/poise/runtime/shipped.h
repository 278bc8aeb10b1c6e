// Where the shipped configuration is (host, filter, driver, camera and QoS files): the directory
// `share/poise` of the prefix the running executable was installed into (<prefix>/bin/poise ->
// <prefix>/share/poise), so an installed tree works wherever it was installed (/usr in the Debian
// package, any `cmake --install --prefix`). A build tree has build/share/poise, a link to the
// source tree's config/ made at configure time, so build/bin/poise sees the same layout.
// docs/DEPLOY.md "Host files".
#pragma once

#include <string>

namespace poise::runtime {

/// The shipped configuration directory of the running executable, or "" when there is none
/// (a program that is neither installed nor in build/bin, e.g. a test executable).
std::string shipped_config_dir();

/// The same for an executable at `exe` (an absolute path): `<dir of exe>/../share/poise`,
/// normalised, when that is a directory; else "".
std::string shipped_config_dir_of(const std::string& exe);

/// A shipped file named by its path inside the shipped configuration (e.g. "drivers/imu.yaml"),
/// for messages: its real path when the shipped directory exists, else "<relative> of the shipped
/// configuration (config/<relative> in the source tree)".
std::string shipped_file_hint(const std::string& relative);

}  // namespace poise::runtime
