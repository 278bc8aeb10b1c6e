// Component `foxglove_bridge` (host files; `poise foxglove` alone): a Foxglove WebSocket server
// (poise/foxglove/server.h) showing the DDS domain live (docs/FOXGLOVE.md).
//  - every poise (and ROS 2 IDL) topic seen on the domain is a channel: encoding "cdr", schema
//    encoding "omgidl", schema name the DDS type name, schema the flattened IDL (the same text
//    `poise record` writes into MCAP); the payloads are the DDS serialized bytes, forwarded
//    verbatim (no decode, no re-encode), with the reception time (CLOCK_REALTIME, ns);
//  - for the panels: `foxglove/tf` (foxglove.FrameTransform, JSON) world -> each attitude/pose
//    estimate's body frame and the camera; `foxglove/attitude/<frame>` (poise.AttitudePlot,
//    JSON) per attitude topic: angles, magnetic disturbance, magnetometer trust;
//  - a topic whose writers are all gone for `unadvertise_after_s` is unadvertised (and advertised
//    again, same id, when a writer comes back).
// The DDS side is a separate observer participant with best-effort raw readers: the bridge never
// back-pressures a writer. Payloads are checked against the IDL before they go out (a malformed
// one is counted, never forwarded).
//
//   - type: foxglove_bridge
//     params:
//       port: 8765              # TCP port (0: any free port, printed at start)
//       address: 0.0.0.0        # listen address (127.0.0.1: this host only)
//       topics: []              # topics to bridge (empty: every topic seen)
//       world_frame: world      # parent frame of the transforms (ENU)
//       frame_spacing_m: 0.6    # display offset between attitude-only frames (x, m)
//       stamps: realtime        # or sensor: panel stamps = stamp_ns (+ REALTIME - MONOTONIC)
//       max_clients: 16
//       queue_frames: 2000      # per client: frames waiting; the oldest is dropped beyond
//       queue_bytes: 4194304    # per client: bytes waiting; the oldest is dropped beyond
//       socket_buffer_bytes: 1048576   # per client: bytes handed to the socket layer at most
//       max_request_bytes: 65536       # larger client requests are refused with an error status
//       max_requests_per_s: 20         # per client; more are refused unread (counted)
//       idle_timeout_s: 30             # a client without a subscription this long is closed (0: never)
//       unadvertise_after_s: 5
//       diagnostics_period_s: 1
#pragma once

#include "poise/foxglove/server.h"
#include "poise/runtime/component.h"

#include <string>
#include <vector>

namespace poise::foxglove {

struct BridgeConfig {
  ServerOptions server;
  std::vector<std::string> topics;  ///< empty: all
  std::string world_frame = "world";
  double frame_spacing_m = 0.6;
  bool realtime_stamps = true;
  double unadvertise_after_s = 5.0;
  double diagnostics_period_s = 1.0;
};

/// Parses and checks the parameters; throws runtime::ConfigError naming the key.
BridgeConfig parse_bridge_config(const runtime::ComponentSpec& spec);

void register_foxglove_bridge(runtime::ComponentRegistry& registry);

}  // namespace poise::foxglove
