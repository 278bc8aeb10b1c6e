// A DDS participant that watches a domain: discovers every writer (topic, type, QoS) through the
// participant's discovery callbacks and subscribes to any topic with the raw type, using reader
// QoS compatible with the writers found. The common base of `poise topics`, `poise echo` and the
// recorder.
#pragma once

#include "poise/schema/idl_schema.h"
#include "poise/schema/raw_type.h"

#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace poise::schema {

/// A remote DataWriter as announced by discovery.
struct DiscoveredWriter {
  std::string guid;   // printable GUID
  std::string topic;
  std::string type;   // DDS type name, e.g. "poise::msg::ImuSample"
  bool keyed = false;
  bool reliable = false;
  bool transient_local = false;   // durability TRANSIENT_LOCAL or stronger
  bool exclusive_ownership = false;
  std::vector<std::string> partitions;
  std::uint32_t max_serialized_size = 0;  // as announced (0 = unknown)
};

struct ObserverOptions {
  int domain = 0;
  /// poise_dds participant profile ("" = $POISE_DDS_PROFILE, else poise_default).
  std::string profile;
  /// QoS profiles file ("" = $POISE_QOS_FILE, else the built-in copy).
  std::string qos_file;
  std::string name = "poise-observer";
};

/// Reader QoS choices for subscribe().
struct RawReaderOptions {
  /// Best effort matches both reliable and best-effort writers; reliable only reliable writers.
  bool reliable = false;
  /// Transient-local (late-joiner history) only matches transient-local writers.
  bool transient_local = false;
  int history_depth = 100;
};

class TopicObserver {
 public:
  /// Throws poise::dds::DdsError (std::runtime_error) when the participant cannot be created.
  explicit TopicObserver(const ObserverOptions& options);
  ~TopicObserver();
  TopicObserver(const TopicObserver&) = delete;
  TopicObserver& operator=(const TopicObserver&) = delete;

  /// Writers currently alive on the domain (other participants only), in discovery order.
  [[nodiscard]] std::vector<DiscoveredWriter> writers() const;
  /// Waits up to `timeout` for a writer of `topic`; polls `cancelled` (e.g. Ctrl-C) every 20 ms.
  std::optional<DiscoveredWriter> wait_for_writer(const std::string& topic,
                                                  std::chrono::milliseconds timeout,
                                                  const std::function<bool()>& cancelled = {});

  /// Called from a Fast DDS thread for every valid sample.
  using SampleCallback =
      std::function<void(const poise::dds::RawSample&, const eprosima::fastdds::dds::SampleInfo&)>;
  /// Called from a Fast DDS thread for every malformed sample, with the reason (payload_problem).
  using RejectCallback = std::function<void(const poise::dds::RawSample&,
                                            const eprosima::fastdds::dds::SampleInfo&,
                                            const std::string& problem)>;

  /// Subscribes to `writer.topic` with the raw type `writer.type`, keyed iff the writer is (keys
  /// computed from `table` when it knows the type with the same keyed-ness), in the writer's
  /// partitions and ownership kind. `table` (may be null) must outlive the observer. When the
  /// table knows the type, every payload is checked against it first (payload_problem()): a
  /// malformed one is counted (counts()) and given to `rejected` (if set), never to `callback`.
  /// At most one reader per topic; throws poise::dds::DdsError on failure or if the topic is
  /// already subscribed.
  void subscribe(const DiscoveredWriter& writer, const TypeTable* table, SampleCallback callback,
                 const RawReaderOptions& options = {}, RejectCallback rejected = {});
  /// Number of writers matched by the reader of `topic` (0 if not subscribed).
  [[nodiscard]] int matched_writers(const std::string& topic) const;

  /// Samples of a subscribed topic so far: handed to the callback, and rejected as malformed.
  struct Counts {
    std::uint64_t accepted = 0;
    std::uint64_t malformed = 0;
  };
  [[nodiscard]] Counts counts(const std::string& topic) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace poise::schema
