// A Foxglove WebSocket server (`foxglove.websocket.v1`) on websocketpp + standalone asio (Debian's
// libwebsocketpp-dev, libasio-dev): no WebSocket framing of our own. No DDS here: the bridge
// component feeds it channels and payloads (poise/foxglove/bridge.h).
//
// Threads: one network thread runs asio; publish() may be called from any thread (the DDS
// listeners) and never waits for the network: it copies the payload into each subscribed
// client's bounded FrameQueue (drop oldest, counted) and wakes the network thread. The network
// thread moves frames from a queue into websocketpp only while that connection's buffered
// amount is under `max_socket_buffer_bytes`, so a stalled client holds at most its queue plus
// that much, and never slows the publisher or the other clients.
//
// Client frames: text frames up to `max_request_bytes` are parsed (ClientSession), longer ones up
// to `max_frame_bytes` are refused with an error status; beyond `max_frame_bytes` websocketpp
// closes the connection with 1009 (message too big) before reading it. Clients that do not offer
// the subprotocol are refused at the handshake (HTTP 400), and past `max_clients` (HTTP 503).
// Budgets per client (issue 33: one client flooding invalid ids cut another from 2200 to 377
// frames/s; 16 idle clients locked everyone out): at most `max_requests_per_s` requests are
// parsed per second (the rest refused unread, counted, one status per second), a request lists at
// most ClientSession::kMaxEntriesPerRequest entries and gets one status, and a client without a
// subscription for `idle_timeout_s` is closed.
#pragma once

#include "poise/foxglove/protocol.h"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

namespace poise::foxglove {

/// The server cannot start (address, port in use); the message says which and what to do.
class ServerError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ServerOptions {
  std::string address = "0.0.0.0";  ///< listen address (0.0.0.0: every interface)
  std::uint16_t port = 8765;        ///< 0: an ephemeral port (see Server::port())
  std::string name = "poise";       ///< serverInfo name
  std::size_t max_clients = 16;
  std::size_t queue_frames = 2000;           ///< per client, frames waiting for the socket
  std::size_t queue_bytes = 4u << 20;        ///< per client, bytes waiting for the socket
  std::size_t max_socket_buffer_bytes = 1u << 20;  ///< per client, handed to websocketpp
  std::size_t max_request_bytes = 64u << 10;       ///< a larger text frame is refused (status)
  std::size_t max_frame_bytes = 1u << 20;          ///< a larger frame closes the connection (1009)
  /// Per client: requests parsed per second, sustained (a burst of as many is allowed). Requests
  /// beyond are refused unread and counted, with at most one error status per second.
  double max_requests_per_s = 20.0;
  /// A client with no subscription for this long is closed (1008, "idle: ..."): connections
  /// that never subscribe cannot hold the max_clients places. 0: never.
  double idle_timeout_s = 30.0;
};

struct ClientStats {
  std::uint32_t id = 0;         ///< 1, 2, ... in order of connection
  std::string remote;           ///< address:port
  std::size_t subscriptions = 0;
  std::uint64_t sent = 0;       ///< message frames handed to the socket
  std::uint64_t dropped = 0;    ///< message frames dropped (queue full: the client is too slow)
  std::uint64_t errors = 0;     ///< refused requests (error statuses sent)
  std::uint64_t throttled = 0;  ///< requests refused unread: over max_requests_per_s
  std::size_t queued = 0;       ///< frames waiting
  std::size_t buffered_bytes = 0;  ///< bytes websocketpp still has to write
};

struct ServerStats {
  std::vector<ClientStats> clients;  ///< connected now
  std::size_t channels = 0;
  std::uint64_t connections = 0;     ///< accepted since start
  std::uint64_t refused = 0;         ///< handshakes refused (subprotocol, max_clients)
  std::uint64_t sent = 0;            ///< message frames, all clients, since start
  std::uint64_t dropped = 0;         ///< message frames dropped, all clients, since start
  std::uint64_t errors = 0;          ///< refused client requests, since start
  std::uint64_t throttled = 0;       ///< of which refused unread (request budget), since start
  std::uint64_t idle_closed = 0;     ///< clients closed for idling (idle_timeout_s), since start
};

class Server {
 public:
  /// Binds and listens; throws ServerError when it cannot.
  explicit Server(ServerOptions options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  /// Starts the network thread (accepting clients).
  void start();
  /// Closes every connection and stops the network thread (idempotent).
  void stop();
  /// The port listened on (the ephemeral one when options.port was 0).
  [[nodiscard]] std::uint16_t port() const;

  /// Adds a channel (its id: `channel.id` if non-zero and free, else the next free id) and
  /// advertises it to every client.
  std::uint32_t add_channel(Channel channel);
  /// Unadvertises a channel; the clients' subscriptions to it end.
  void remove_channel(std::uint32_t id);
  /// True when at least one client is subscribed to `channel` (cheap: check before encoding).
  [[nodiscard]] bool subscribed(std::uint32_t channel) const;
  /// Queues the payload for every client subscribed to `channel`; never blocks on the network.
  void publish(std::uint32_t channel, std::uint64_t receive_ns, const std::uint8_t* data, std::size_t size);

  [[nodiscard]] ServerStats stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace poise::foxglove
