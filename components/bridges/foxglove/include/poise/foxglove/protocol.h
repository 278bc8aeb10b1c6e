// The Foxglove WebSocket protocol (`foxglove.websocket.v1`), server side, without any socket:
// the JSON messages the server sends, the binary Message Data frame, one client's subscriptions
// and the checking of everything a client sends (docs/FOXGLOVE.md). Pure C++17 + nlohmann-json.
//
// Every client frame is hostile: handle_text() never throws, whatever the bytes; a frame that is
// not a valid request (not JSON, not an object, no string `op`, an unknown or unsupported op,
// malformed subscriptions, unknown channels, reused ids) gets an error status naming the problem
// and changes nothing else.
#pragma once

#include <nlohmann/json_fwd.hpp>

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace poise::foxglove {

/// The subprotocol a client must offer and the server selects.
inline constexpr const char* kSubprotocol = "foxglove.websocket.v1";
/// Opcode of the binary Message Data frame (server -> client).
inline constexpr std::uint8_t kMessageDataOpcode = 0x01;
/// Bytes before the payload in a Message Data frame: opcode, subscription id, receive time.
inline constexpr std::size_t kMessageDataHeaderBytes = 1 + 4 + 8;

enum class StatusLevel : int { kInfo = 0, kWarning = 1, kError = 2 };

/// One advertised channel.
struct Channel {
  std::uint32_t id = 0;
  std::string topic;
  std::string encoding;         ///< message encoding: "cdr" (poise topics) or "json"
  std::string schema_name;      ///< "poise::msg::ImuSample", "foxglove.FrameTransform", ...
  std::string schema;           ///< the schema text (omgidl IDL, or a JSON schema)
  std::string schema_encoding;  ///< "omgidl" or "jsonschema"
};

/// {"op":"serverInfo",...}: no optional capability (no client publishing, parameters, services),
/// `metadata` as given, `sessionId` to tell a reconnection from a new server.
std::string server_info_json(const std::string& name, const std::string& session_id,
                             const std::map<std::string, std::string>& metadata = {});
/// {"op":"advertise","channels":[...]} (an empty list is valid: sent on connection).
std::string advertise_json(const std::vector<Channel>& channels);
std::string unadvertise_json(const std::vector<std::uint32_t>& channel_ids);
/// {"op":"status","level":L,"message":M} (invalid UTF-8 in M is replaced, never thrown on).
std::string status_json(StatusLevel level, const std::string& message);

/// The Message Data frame: 0x01, subscription id (u32 LE), receive time (u64 LE, ns), payload.
std::string message_data_frame(std::uint32_t subscription_id, std::uint64_t receive_ns,
                               const std::uint8_t* payload, std::size_t size);

/// One client's subscriptions (subscription id -> channel id, one per channel) and the handling
/// of its requests.
class ClientSession {
 public:
  struct Reply {
    StatusLevel level;
    std::string message;
  };
  struct Result {
    std::vector<Reply> replies;       ///< status messages to send back (errors, warnings)
    bool subscriptions_changed = false;
  };

  /// Handles one text frame. `channel_known(id)` says whether a channel is advertised. Never throws.
  Result handle_text(std::string_view text, const std::function<bool(std::uint32_t)>& channel_known);
  /// A binary frame: this server takes none (no clientPublish / services capability).
  static Reply binary_refused(std::size_t size);
  /// Drops the subscriptions of a channel that is no longer advertised; true if there was one.
  bool channel_removed(std::uint32_t channel_id);

  /// Subscription id -> channel id.
  [[nodiscard]] const std::map<std::uint32_t, std::uint32_t>& subscriptions() const { return subscriptions_; }
  /// The subscription of `channel_id`, if the client has one.
  [[nodiscard]] std::optional<std::uint32_t> subscription_for(std::uint32_t channel_id) const;

  /// Largest number of simultaneous subscriptions of one client (bounds the state a client can make).
  static constexpr std::size_t kMaxSubscriptions = 4096;
  /// Largest number of entries (subscriptions, ids) one subscribe / unsubscribe may list; a longer
  /// list is refused whole with one error status, unread. Each request is answered with at most
  /// one status per kind (the count refused and the first reason), never one per entry.
  static constexpr std::size_t kMaxEntriesPerRequest = 256;

 private:
  void subscribe(const nlohmann::json& request, const std::function<bool(std::uint32_t)>& channel_known, Result& out);
  void unsubscribe(const nlohmann::json& request, Result& out);
  std::map<std::uint32_t, std::uint32_t> subscriptions_;
};

/// A client's outgoing frames: bounded in count and bytes; when full, the OLDEST frame is dropped
/// and counted (a slow client sees gaps, never an ever-growing backlog). Not thread-safe.
class FrameQueue {
 public:
  FrameQueue(std::size_t max_frames, std::size_t max_bytes);
  /// Appends, dropping the oldest frames while over either limit (a frame larger than max_bytes
  /// alone is kept: the queue then holds it only).
  void push(std::string frame);
  /// Removes the oldest frame into `out`; false when empty.
  bool pop(std::string& out);
  [[nodiscard]] std::size_t size() const { return frames_.size(); }
  [[nodiscard]] std::size_t bytes() const { return bytes_; }
  [[nodiscard]] std::uint64_t dropped() const { return dropped_; }
  [[nodiscard]] bool empty() const { return size() == 0; }

 private:
  std::size_t max_frames_;
  std::size_t max_bytes_;
  std::deque<std::string> frames_;
  std::size_t bytes_ = 0;
  std::uint64_t dropped_ = 0;
};

}  // namespace poise::foxglove
