#include "poise/foxglove/server.h"

#ifndef ASIO_STANDALONE
#define ASIO_STANDALONE
#endif
#ifndef _WEBSOCKETPP_CPP11_STL_
#define _WEBSOCKETPP_CPP11_STL_
#endif
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <map>
#include <mutex>
#include <random>
#include <thread>

namespace poise::foxglove {

namespace {

using WsServer = websocketpp::server<websocketpp::config::asio>;
using Hdl = websocketpp::connection_hdl;
namespace opcode = websocketpp::frame::opcode;

/// Frames moved from a client's queue into websocketpp per turn of the network thread.
constexpr std::size_t kFramesPerTurn = 256;
/// Period of the network thread's retry of clients whose socket buffer was full.
constexpr auto kRetryPeriod = std::chrono::milliseconds(5);

std::string session_id() {
  std::random_device rd;
  return std::to_string(std::chrono::system_clock::now().time_since_epoch().count()) + "-" +
         std::to_string(rd());
}

}  // namespace

struct Server::Impl {
  using Clock = std::chrono::steady_clock;
  struct Client {
    Client(std::uint32_t i, Hdl h, std::string r, const ServerOptions& o)
        : id(i), hdl(std::move(h)), remote(std::move(r)), queue(o.queue_frames, o.queue_bytes) {}
    std::uint32_t id;
    Hdl hdl;
    std::string remote;
    ClientSession session;
    FrameQueue queue;
    bool flush_posted = false;
    std::uint64_t sent = 0;
    std::uint64_t errors = 0;
    std::uint64_t throttled = 0;
    // request budget: a token bucket of max_requests_per_s, refilled continuously
    double tokens = 0.0;
    Clock::time_point refilled = Clock::now();
    Clock::time_point throttle_said{};  // last "over budget" status sent
    Clock::time_point idle_since = Clock::now();  // without subscription since
  };
  using ClientPtr = std::shared_ptr<Client>;

  ServerOptions options;
  std::string session = session_id();
  WsServer ws;
  std::unique_ptr<asio::steady_timer> timer;
  std::thread thread;
  std::atomic<bool> running{false};
  std::uint16_t bound_port = 0;

  mutable std::mutex mutex;  // everything below
  std::map<Hdl, ClientPtr, std::owner_less<Hdl>> clients;
  std::map<std::uint32_t, Channel> channels;      // advertised (network thread adds/removes)
  std::vector<std::uint32_t> reserved_ids;        // ids given out by add_channel (any thread)
  std::uint32_t next_channel_id = 1;
  std::uint32_t next_client_id = 1;
  // channel -> (client, subscription id), rebuilt when subscriptions change
  std::map<std::uint32_t, std::vector<std::pair<ClientPtr, std::uint32_t>>> subscribers;
  std::uint64_t connections = 0;
  std::uint64_t refused = 0;
  std::uint64_t sent_closed = 0;     // counts of clients that left
  std::uint64_t dropped_closed = 0;
  std::uint64_t errors_closed = 0;
  std::uint64_t throttled_closed = 0;
  std::uint64_t idle_closed = 0;
  Clock::time_point idle_checked = Clock::now();

  explicit Impl(ServerOptions o) : options(std::move(o)) {
    ws.clear_access_channels(websocketpp::log::alevel::all);
    ws.clear_error_channels(websocketpp::log::elevel::all);
    ws.init_asio();
    ws.set_reuse_addr(true);
    ws.set_max_message_size(options.max_frame_bytes);
    ws.set_socket_init_handler([](Hdl, asio::ip::tcp::socket& s) {
      asio::error_code ec;
      s.set_option(asio::ip::tcp::no_delay(true), ec);
    });
    ws.set_validate_handler([this](Hdl h) { return on_validate(h); });
    ws.set_open_handler([this](Hdl h) { on_open(h); });
    ws.set_close_handler([this](Hdl h) { on_gone(h); });
    ws.set_fail_handler([this](Hdl h) { on_gone(h); });
    ws.set_message_handler([this](Hdl h, WsServer::message_ptr m) {
      try {
        on_message(h, m);
      } catch (const std::exception&) {
        // bad_alloc or a websocketpp error on a closing connection: that request is lost only.
      }
    });
    asio::error_code ec;
    const asio::ip::address address = asio::ip::make_address(options.address, ec);
    if (ec) {
      throw ServerError("foxglove: '" + options.address + "' is not an IP address (address:)");
    }
    ws.listen(asio::ip::tcp::endpoint(address, options.port), ec);
    if (ec) {
      throw ServerError("foxglove: cannot listen on " + options.address + ":" +
                        std::to_string(options.port) + ": " + ec.message() +
                        " (another server on that port? choose one with port:)");
    }
    ws.start_accept(ec);
    if (ec) {
      throw ServerError("foxglove: cannot accept connections: " + ec.message());
    }
    const auto local = ws.get_local_endpoint(ec);
    bound_port = ec ? options.port : local.port();
    timer = std::make_unique<asio::steady_timer>(ws.get_io_service());
  }

  // --- network thread -------------------------------------------------------------------------

  bool on_validate(Hdl h) {
    WsServer::connection_ptr con = ws.get_con_from_hdl(h);
    const auto& offered = con->get_requested_subprotocols();
    std::lock_guard<std::mutex> lock(mutex);
    if (std::find(offered.begin(), offered.end(), kSubprotocol) == offered.end()) {
      con->set_status(websocketpp::http::status_code::bad_request);
      con->set_body(std::string("this is a Foxglove WebSocket server: offer the subprotocol ") + kSubprotocol + "\n");
      ++refused;
      return false;
    }
    if (clients.size() >= options.max_clients) {
      con->set_status(websocketpp::http::status_code::service_unavailable);
      con->set_body("too many clients (max_clients " + std::to_string(options.max_clients) + ")\n");
      ++refused;
      return false;
    }
    con->select_subprotocol(kSubprotocol);
    return true;
  }

  void on_open(Hdl h) {
    std::vector<Channel> list;
    ClientPtr c;
    {
      std::lock_guard<std::mutex> lock(mutex);
      std::string remote;
      try {
        remote = ws.get_con_from_hdl(h)->get_remote_endpoint();
      } catch (const std::exception&) {
        remote = "?";
      }
      c = std::make_shared<Client>(next_client_id++, h, remote, options);
      c->tokens = std::max(1.0, options.max_requests_per_s);
      clients[h] = c;
      ++connections;
      for (const auto& [id, channel] : channels) {
        list.push_back(channel);
      }
    }
    send_text(*c, server_info_json(options.name, session, {{"poise_channels", std::to_string(list.size())}}));
    send_text(*c, advertise_json(list));
  }

  void on_gone(Hdl h) {
    std::lock_guard<std::mutex> lock(mutex);
    const auto it = clients.find(h);
    if (it == clients.end()) {
      return;
    }
    sent_closed += it->second->sent;
    dropped_closed += it->second->queue.dropped();
    errors_closed += it->second->errors;
    throttled_closed += it->second->throttled;
    clients.erase(it);
    rebuild_subscribers();
  }

  void on_message(Hdl h, const WsServer::message_ptr& m) {
    ClientPtr c;
    std::vector<ClientSession::Reply> replies;
    {
      std::lock_guard<std::mutex> lock(mutex);
      const auto it = clients.find(h);
      if (it == clients.end()) {
        return;
      }
      c = it->second;
      const std::string& payload = m->get_payload();
      if (!take_token(*c)) {
        // over budget: not parsed; one status per second says so
        ++c->throttled;
        ++c->errors;
        const auto now = Clock::now();
        if (now - c->throttle_said < std::chrono::seconds(1)) {
          return;
        }
        c->throttle_said = now;
        replies.push_back({StatusLevel::kError, "requests refused unread: more than " +
                                                    std::to_string(static_cast<long>(options.max_requests_per_s)) +
                                                    " per second from this client (" + std::to_string(c->throttled) +
                                                    " so far)"});
      } else if (m->get_opcode() != opcode::text) {
        replies.push_back(ClientSession::binary_refused(payload.size()));
      } else if (payload.size() > options.max_request_bytes) {
        replies.push_back({StatusLevel::kError, "request of " + std::to_string(payload.size()) +
                                                    " bytes refused (limit " +
                                                    std::to_string(options.max_request_bytes) + ")"});
      } else {
        auto result = c->session.handle_text(payload, [this](std::uint32_t id) { return channels.count(id) != 0; });
        if (result.subscriptions_changed) {
          rebuild_subscribers();
        }
        replies = std::move(result.replies);
      }
      for (const auto& r : replies) {
        if (r.level == StatusLevel::kError && r.message.rfind("requests refused unread", 0) != 0) {
          ++c->errors;
        }
      }
    }
    for (const auto& r : replies) {
      send_text(*c, status_json(r.level, r.message));
    }
  }

  /// One request of the client's budget (mutex held); false when it is spent.
  bool take_token(Client& c) const {
    const auto now = Clock::now();
    const double burst = std::max(1.0, options.max_requests_per_s);
    c.tokens = std::min(burst, c.tokens + std::chrono::duration<double>(now - c.refilled).count() *
                                              options.max_requests_per_s);
    c.refilled = now;
    if (c.tokens < 1.0) {
      return false;
    }
    c.tokens -= 1.0;
    return true;
  }

  /// Closes the clients without a subscription for idle_timeout_s (checked about once a second).
  void close_idle() {
    const auto now = Clock::now();
    if (options.idle_timeout_s <= 0.0 || now - idle_checked < std::chrono::seconds(1)) {
      return;
    }
    idle_checked = now;
    const auto limit = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options.idle_timeout_s));
    std::vector<Hdl> idle;
    {
      std::lock_guard<std::mutex> lock(mutex);
      for (const auto& [h, c] : clients) {
        if (!c->session.subscriptions().empty()) {
          c->idle_since = now;
        } else if (now - c->idle_since > limit) {
          idle.push_back(h);
          c->idle_since = now;  // closing: not again
        }
      }
      idle_closed += idle.size();
    }
    for (const auto& h : idle) {
      std::error_code ec;
      ws.close(h, websocketpp::close::status::policy_violation,
               "idle: no subscription for " + std::to_string(static_cast<long>(options.idle_timeout_s)) + " s", ec);
    }
  }

  std::size_t buffered(const Hdl& h) {
    std::error_code ec;
    WsServer::connection_ptr con = ws.get_con_from_hdl(h, ec);
    return ec || !con ? 0 : con->get_buffered_amount();
  }

  /// A control message; dropped when the client's socket buffer is full (a client that does not
  /// read cannot make the server hold its replies).
  void send_text(Client& c, const std::string& text) {
    if (buffered(c.hdl) > options.max_socket_buffer_bytes) {
      return;
    }
    std::error_code ec;
    ws.send(c.hdl, text, opcode::text, ec);
  }

  /// Moves queued frames into websocketpp while the socket buffer has room.
  void flush(const ClientPtr& c) {
    std::vector<std::string> frames;
    {
      std::lock_guard<std::mutex> lock(mutex);
      c->flush_posted = false;
      std::size_t pending = buffered(c->hdl);
      std::string f;
      while (frames.size() < kFramesPerTurn && pending < options.max_socket_buffer_bytes && c->queue.pop(f)) {
        pending += f.size();
        frames.push_back(std::move(f));
      }
    }
    std::uint64_t sent = 0;
    for (const auto& f : frames) {
      std::error_code ec;
      ws.send(c->hdl, f, opcode::binary, ec);
      sent += ec ? 0 : 1;
    }
    std::lock_guard<std::mutex> lock(mutex);
    c->sent += sent;
  }

  void arm_timer() {
    timer->expires_after(kRetryPeriod);
    timer->async_wait([this](const asio::error_code& ec) {
      if (ec || !running.load()) {
        return;
      }
      std::vector<ClientPtr> waiting;
      {
        std::lock_guard<std::mutex> lock(mutex);
        for (const auto& [h, c] : clients) {
          if (!c->queue.empty() && !c->flush_posted) {
            waiting.push_back(c);
          }
        }
      }
      for (const auto& c : waiting) {
        flush(c);
      }
      close_idle();
      arm_timer();
    });
  }

  void rebuild_subscribers() {  // mutex held
    subscribers.clear();
    for (const auto& [h, c] : clients) {
      for (const auto& [sub, channel] : c->session.subscriptions()) {
        subscribers[channel].emplace_back(c, sub);
      }
    }
  }

  void advertise(const Channel& channel) {
    std::vector<ClientPtr> all;
    {
      std::lock_guard<std::mutex> lock(mutex);
      channels[channel.id] = channel;
      for (const auto& [h, c] : clients) {
        all.push_back(c);
      }
    }
    const std::string text = advertise_json({channel});
    for (const auto& c : all) {
      send_text(*c, text);
    }
  }

  void unadvertise(std::uint32_t id) {
    std::vector<ClientPtr> all;
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (channels.erase(id) == 0) {
        return;
      }
      for (const auto& [h, c] : clients) {
        c->session.channel_removed(id);
        all.push_back(c);
      }
      rebuild_subscribers();
      reserved_ids.erase(std::remove(reserved_ids.begin(), reserved_ids.end(), id), reserved_ids.end());
    }
    const std::string text = unadvertise_json({id});
    for (const auto& c : all) {
      send_text(*c, text);
    }
  }

  void close_all() {
    std::error_code ec;
    ws.stop_listening(ec);
    timer->cancel();
    std::vector<Hdl> handles;
    {
      std::lock_guard<std::mutex> lock(mutex);
      for (const auto& [h, c] : clients) {
        handles.push_back(h);
      }
    }
    for (const auto& h : handles) {
      ws.close(h, websocketpp::close::status::going_away, "server stopping", ec);
    }
  }
};

Server::Server(ServerOptions options) : impl_(std::make_unique<Impl>(std::move(options))) {}

Server::~Server() { stop(); }

void Server::start() {
  if (impl_->running.exchange(true)) {
    return;
  }
  impl_->arm_timer();
  impl_->thread = std::thread([this] {
    while (true) {
      try {
        impl_->ws.run();
        return;
      } catch (const std::exception&) {
        // A handler threw (it should not): keep serving the other clients.
      }
    }
  });
}

void Server::stop() {
  if (!impl_->running.exchange(false)) {
    return;
  }
  asio::post(impl_->ws.get_io_service(), [this] { impl_->close_all(); });
  // Let the close handshakes go out, then end the loop.
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  impl_->ws.stop();
  if (impl_->thread.joinable()) {
    impl_->thread.join();
  }
}

std::uint16_t Server::port() const { return impl_->bound_port; }

std::uint32_t Server::add_channel(Channel channel) {
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    auto& ids = impl_->reserved_ids;
    if (channel.id == 0 || std::find(ids.begin(), ids.end(), channel.id) != ids.end()) {
      while (std::find(ids.begin(), ids.end(), impl_->next_channel_id) != ids.end()) {
        ++impl_->next_channel_id;
      }
      channel.id = impl_->next_channel_id++;
    }
    ids.push_back(channel.id);
  }
  const std::uint32_t id = channel.id;
  asio::post(impl_->ws.get_io_service(), [this, channel = std::move(channel)] { impl_->advertise(channel); });
  return id;
}

void Server::remove_channel(std::uint32_t id) {
  asio::post(impl_->ws.get_io_service(), [this, id] { impl_->unadvertise(id); });
}

bool Server::subscribed(std::uint32_t channel) const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->subscribers.count(channel) != 0;
}

void Server::publish(std::uint32_t channel, std::uint64_t receive_ns, const std::uint8_t* data, std::size_t size) {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  const auto it = impl_->subscribers.find(channel);
  if (it == impl_->subscribers.end()) {
    return;
  }
  for (const auto& [client, sub] : it->second) {
    client->queue.push(message_data_frame(sub, receive_ns, data, size));
    if (!client->flush_posted && impl_->running.load()) {
      client->flush_posted = true;
      asio::post(impl_->ws.get_io_service(), [this, c = client] { impl_->flush(c); });
    }
  }
}

ServerStats Server::stats() const {
  ServerStats s;
  std::vector<std::pair<Hdl, ClientStats>> list;
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    s.channels = impl_->channels.size();
    s.connections = impl_->connections;
    s.refused = impl_->refused;
    s.sent = impl_->sent_closed;
    s.dropped = impl_->dropped_closed;
    s.errors = impl_->errors_closed;
    s.throttled = impl_->throttled_closed;
    s.idle_closed = impl_->idle_closed;
    for (const auto& [h, c] : impl_->clients) {
      ClientStats cs;
      cs.id = c->id;
      cs.remote = c->remote;
      cs.subscriptions = c->session.subscriptions().size();
      cs.sent = c->sent;
      cs.dropped = c->queue.dropped();
      cs.errors = c->errors;
      cs.throttled = c->throttled;
      cs.queued = c->queue.size();
      s.sent += cs.sent;
      s.dropped += cs.dropped;
      s.errors += cs.errors;
      s.throttled += cs.throttled;
      list.emplace_back(h, cs);
    }
  }
  for (auto& [h, cs] : list) {
    cs.buffered_bytes = impl_->buffered(h);
    s.clients.push_back(cs);
  }
  std::sort(s.clients.begin(), s.clients.end(), [](const ClientStats& a, const ClientStats& b) { return a.id < b.id; });
  return s;
}

}  // namespace poise::foxglove
