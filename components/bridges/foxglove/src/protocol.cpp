#include "poise/foxglove/protocol.h"

#include <nlohmann/json.hpp>

#include <limits>

namespace poise::foxglove {

using nlohmann::json;

namespace {

std::string dump(const json& j) { return j.dump(-1, ' ', false, json::error_handler_t::replace); }

/// A JSON number that is an integer in [0, 2^32) (a subscription or channel id) into `out`.
bool read_u32(const json& j, std::uint32_t& out) {
  std::uint64_t v = 0;
  if (j.is_number_unsigned()) {
    v = j.get<std::uint64_t>();
  } else if (j.is_number_integer() && j.get<std::int64_t>() >= 0) {
    v = static_cast<std::uint64_t>(j.get<std::int64_t>());
  } else {
    return false;
  }
  if (v > std::numeric_limits<std::uint32_t>::max()) {
    return false;
  }
  out = static_cast<std::uint32_t>(v);
  return true;
}

/// Member `key` of object `j` read by read_u32.
bool read_u32(const json& j, const char* key, std::uint32_t& out) {
  if (!j.is_object()) {
    return false;
  }
  const auto it = j.find(key);
  return it != j.end() && read_u32(*it, out);
}

void put_le(std::string& out, std::uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) {
    out.push_back(static_cast<char>((v >> (8 * i)) & 0xFFu));
  }
}

}  // namespace

std::string server_info_json(const std::string& name, const std::string& session_id,
                             const std::map<std::string, std::string>& metadata) {
  json j = {{"op", "serverInfo"},
            {"name", name},
            {"capabilities", json::array()},
            {"sessionId", session_id}};
  j["metadata"] = json::object();
  for (const auto& [k, v] : metadata) {
    j["metadata"][k] = v;
  }
  return dump(j);
}

std::string advertise_json(const std::vector<Channel>& channels) {
  json list = json::array();
  for (const auto& c : channels) {
    list.push_back({{"id", c.id},
                    {"topic", c.topic},
                    {"encoding", c.encoding},
                    {"schemaName", c.schema_name},
                    {"schema", c.schema},
                    {"schemaEncoding", c.schema_encoding}});
  }
  return dump({{"op", "advertise"}, {"channels", std::move(list)}});
}

std::string unadvertise_json(const std::vector<std::uint32_t>& channel_ids) {
  return dump({{"op", "unadvertise"}, {"channelIds", channel_ids}});
}

std::string status_json(StatusLevel level, const std::string& message) {
  return dump({{"op", "status"}, {"level", static_cast<int>(level)}, {"message", message}});
}

std::string message_data_frame(std::uint32_t subscription_id, std::uint64_t receive_ns,
                               const std::uint8_t* payload, std::size_t size) {
  std::string frame;
  frame.reserve(kMessageDataHeaderBytes + size);
  frame.push_back(static_cast<char>(kMessageDataOpcode));
  put_le(frame, subscription_id, 4);
  put_le(frame, receive_ns, 8);
  frame.append(reinterpret_cast<const char*>(payload), size);
  return frame;
}

ClientSession::Result ClientSession::handle_text(std::string_view text,
                                                 const std::function<bool(std::uint32_t)>& channel_known) {
  Result out;
  // No exceptions: a parse error gives a discarded value (nlohmann's parser is iterative, so
  // deep nesting cannot exhaust the stack).
  const json request = json::parse(text.begin(), text.end(), nullptr, false);
  if (request.is_discarded()) {
    out.replies.push_back({StatusLevel::kError, "malformed request: not valid JSON (" +
                                                    std::to_string(text.size()) + " bytes)"});
    return out;
  }
  if (!request.is_object()) {
    out.replies.push_back({StatusLevel::kError, "malformed request: not a JSON object"});
    return out;
  }
  const auto op = request.find("op");
  if (op == request.end() || !op->is_string()) {
    out.replies.push_back({StatusLevel::kError, "malformed request: no string field 'op'"});
    return out;
  }
  const std::string name = op->get<std::string>();
  if (name == "subscribe") {
    subscribe(request, channel_known, out);
  } else if (name == "unsubscribe") {
    unsubscribe(request, out);
  } else if (name == "advertise" || name == "unadvertise" || name == "getParameters" ||
             name == "setParameters" || name == "subscribeParameterUpdates" ||
             name == "unsubscribeParameterUpdates" || name == "subscribeConnectionGraph" ||
             name == "unsubscribeConnectionGraph" || name == "fetchAsset") {
    out.replies.push_back({StatusLevel::kError, "op '" + name +
                                                    "' needs a capability this server does not "
                                                    "have (it announces none)"});
  } else {
    out.replies.push_back({StatusLevel::kError, "unknown op '" + name.substr(0, 64) + "'"});
  }
  return out;
}

namespace {
/// One error status for a request, however many of its entries were refused (a flood of invalid
/// ids costs one reply, not one per id): "<op>: N of M refused: <the first reason> (and K more)".
void refused_entries(const char* op, std::size_t refused, std::size_t total, const std::string& first,
                     StatusLevel level, ClientSession::Result& out) {
  if (refused == 0) {
    return;
  }
  std::string message = std::string(op) + ": " + std::to_string(refused) + " of " + std::to_string(total) +
                        " refused: " + first;
  if (refused > 1) {
    message += " (and " + std::to_string(refused - 1) + " more)";
  }
  out.replies.push_back({level, message});
}

/// A request listing more than kMaxEntriesPerRequest entries is refused whole, unread.
bool too_many_entries(const char* op, const json& list, ClientSession::Result& out) {
  if (list.size() <= ClientSession::kMaxEntriesPerRequest) {
    return false;
  }
  out.replies.push_back({StatusLevel::kError, std::string(op) + ": " + std::to_string(list.size()) +
                                                  " entries in one request, more than the " +
                                                  std::to_string(ClientSession::kMaxEntriesPerRequest) +
                                                  " accepted: refused"});
  return true;
}
}  // namespace

void ClientSession::subscribe(const json& request, const std::function<bool(std::uint32_t)>& channel_known,
                              Result& out) {
  const auto list = request.find("subscriptions");
  if (list == request.end() || !list->is_array()) {
    out.replies.push_back({StatusLevel::kError, "subscribe: 'subscriptions' must be an array"});
    return;
  }
  if (too_many_entries("subscribe", *list, out)) {
    return;
  }
  std::size_t refused = 0;
  std::string first;
  const auto refuse = [&](std::string why) {
    if (refused++ == 0) {
      first = std::move(why);
    }
  };
  for (const json& s : *list) {
    std::uint32_t id = 0;
    std::uint32_t channel = 0;
    if (!read_u32(s, "id", id) || !read_u32(s, "channelId", channel)) {
      refuse("each subscription needs integer 'id' and 'channelId' in [0, 2^32)");
    } else if (!channel_known(channel)) {
      refuse("unknown channel " + std::to_string(channel));
    } else if (subscriptions_.count(id) != 0) {
      refuse("subscription id " + std::to_string(id) + " is already in use");
    } else if (subscription_for(channel)) {
      refuse("channel " + std::to_string(channel) + " is already subscribed (one subscription per channel)");
    } else if (subscriptions_.size() >= kMaxSubscriptions) {
      refuse("too many subscriptions");
    } else {
      subscriptions_[id] = channel;
      out.subscriptions_changed = true;
    }
  }
  refused_entries("subscribe", refused, list->size(), first, StatusLevel::kError, out);
}

void ClientSession::unsubscribe(const json& request, Result& out) {
  const auto list = request.find("subscriptionIds");
  if (list == request.end() || !list->is_array()) {
    out.replies.push_back({StatusLevel::kError, "unsubscribe: 'subscriptionIds' must be an array"});
    return;
  }
  if (too_many_entries("unsubscribe", *list, out)) {
    return;
  }
  std::size_t bad = 0;
  std::size_t unknown = 0;
  std::string first_bad;
  std::string first_unknown;
  for (const json& s : *list) {
    std::uint32_t id = 0;
    if (!read_u32(s, id)) {
      bad += 1;
      first_bad = "ids must be integers in [0, 2^32)";
    } else if (subscriptions_.erase(id) == 0) {
      if (unknown++ == 0) {
        first_unknown = "no subscription " + std::to_string(id);
      }
    } else {
      out.subscriptions_changed = true;
    }
  }
  refused_entries("unsubscribe", bad, list->size(), first_bad, StatusLevel::kError, out);
  refused_entries("unsubscribe", unknown, list->size(), first_unknown, StatusLevel::kWarning, out);
}

ClientSession::Reply ClientSession::binary_refused(std::size_t size) {
  return {StatusLevel::kError, "binary client message of " + std::to_string(size) +
                                   " bytes refused: this server takes none (no clientPublish or "
                                   "services capability)"};
}

bool ClientSession::channel_removed(std::uint32_t channel_id) {
  for (auto it = subscriptions_.begin(); it != subscriptions_.end(); ++it) {
    if (it->second == channel_id) {
      subscriptions_.erase(it);
      return true;
    }
  }
  return false;
}

std::optional<std::uint32_t> ClientSession::subscription_for(std::uint32_t channel_id) const {
  for (const auto& [sub, channel] : subscriptions_) {
    if (channel == channel_id) {
      return sub;
    }
  }
  return std::nullopt;
}

FrameQueue::FrameQueue(std::size_t max_frames, std::size_t max_bytes)
    : max_frames_(max_frames == 0 ? 1 : max_frames), max_bytes_(max_bytes) {}

void FrameQueue::push(std::string frame) {
  bytes_ += frame.size();
  frames_.push_back(std::move(frame));
  while (frames_.size() > 1 && (frames_.size() > max_frames_ || bytes_ > max_bytes_)) {
    bytes_ -= frames_.front().size();
    frames_.pop_front();
    ++dropped_;
  }
}

bool FrameQueue::pop(std::string& out) {
  if (frames_.empty()) {
    return false;
  }
  out = std::move(frames_.front());
  bytes_ -= out.size();
  frames_.pop_front();
  return true;
}

}  // namespace poise::foxglove
