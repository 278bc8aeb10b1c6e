// Readiness for a service manager: `poise run` under systemd (`Type=notify`, the shipped
// `poise@.service`) tells systemd READY=1 only once every component of the host has started, and
// STOPPING=1 before it stops them. Built on libsystemd's sd_notify (Debian libsystemd-dev, found
// at configure time); without it, or when $NOTIFY_SOCKET is unset (not started by systemd), every
// call is a no-op. Install/deploy: docs/DEPLOY.md.
#pragma once

#include "poise/runtime/host.h"

#include <string>

namespace poise::runtime {

/// True when poise was built with libsystemd (sd_notify support).
bool service_notify_supported();

/// Sends `state` (e.g. "READY=1") to the service manager; true if it was sent, false when there is
/// no service manager to tell ($NOTIFY_SOCKET unset) or no sd_notify support. A failure to send
/// to a socket that is set is a warning on stderr (the service manager then times the start out).
bool notify_service(const std::string& state);

/// Starts every component of `host` (Host::start) and only then tells the service manager that
/// the service is ready (READY=1 with a STATUS line). If a component fails to start, the exception
/// propagates and nothing is sent.
void start_and_notify(Host& host);

/// Tells the service manager STOPPING=1, then stops the components (Host::stop).
void stop_and_notify(Host& host);

}  // namespace poise::runtime
