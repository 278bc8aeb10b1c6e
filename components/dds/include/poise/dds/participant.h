// RAII wrappers around Fast DDS entities (habit: entities created in the constructor, which throws
// on failure; delete_contained_entities() in the destructor). QoS comes from XML profiles.
#pragma once

#include "poise/dds/topics.h"

#include <fastdds/dds/core/status/StatusMask.hpp>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace poise::dds {

/// A DDS setup failure (profile missing, entity creation failed); the message says what to do.
class DdsError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// What a participant is for. Nodes create their own endpoints; observers (poise echo, topics,
/// record) must learn every topic, so under a Discovery Server they become a SUPER_CLIENT by
/// themselves (with either configuration method: ROS_DISCOVERY_SERVER or a CLIENT XML profile).
enum class ParticipantRole { kNode, kObserver };

struct ParticipantOptions {
  int domain = 0;
  /// Participant profile; empty: $POISE_DDS_PROFILE, else "poise_default".
  std::string profile;
  /// Profiles XML file; empty: $POISE_QOS_FILE, else the copy of config/qos/poise_profiles.xml
  /// built into the binary.
  std::string qos_file;
  /// Participant name shown to discovery tools (it travels in clear, security or not).
  std::string name = "poise";
  ParticipantRole role = ParticipantRole::kNode;
};

/// DDS Security (authentication PKI-DH, access control Access-Permissions, crypto AES-GCM-GMAC) for
/// one identity of a directory made by tools/security/make_security.sh (docs/NETWORK.md):
///   DIR/ca.pem, DIR/governance.p7s, DIR/IDENTITY/{cert.pem,key.pem,permissions.p7s}.
struct SecurityConfig {
  std::string dir;
  std::string identity;
};

/// Security from the environment: $POISE_SECURITY_DIR and $POISE_SECURITY_IDENTITY. nullopt when
/// POISE_SECURITY_DIR is unset or empty (security off). Throws DdsError if the identity is missing.
/// Every Participant applies it, so any poise process can be made secure without code changes.
std::optional<SecurityConfig> security_from_env();

/// The Fast DDS participant properties (dds.sec.*) for `config`, with file:// URIs. Throws
/// DdsError naming the first file that is missing or unreadable.
std::vector<std::pair<std::string, std::string>> security_properties(const SecurityConfig& config);

/// The first problem found in `config`'s files for `domain`, checked as Fast DDS's builtin
/// plugins check them (certificate issued by DIR/ca.pem and not expired, key matching it, S/MIME
/// signatures of governance.p7s and permissions.p7s by the CA, permissions subject = certificate
/// subject in RFC 2253 form, domain granted); empty when none is found.
std::string check_security_files(const SecurityConfig& config, int domain);

/// The instance of every keyed sample whose key cannot be computed from its bytes (16 bytes 0xFF).
/// Keyed type supports that read untrusted payloads give it instead of failing getKey().
eprosima::fastrtps::rtps::InstanceHandle_t undecodable_instance();

/// Loads the QoS profiles (once per process and file). Throws DdsError if the file is unreadable
/// or invalid. Called by Participant; call it yourself only to fail early.
void load_profiles(const std::string& qos_file = {});

/// The participant profile that `options` resolve to.
std::string resolve_participant_profile(const ParticipantOptions& options);

/// No UDP send of a poise participant ever waits (issue 37): every UDP transport of `qos` gets
/// Fast DDS's `non_blocking_send`, the built-in transports spelled out (UDPv4 + shared memory, as
/// Fast DDS 2.9 makes them) so that theirs does too. A datagram the kernel cannot take at once
/// (the socket's send buffer full, e.g. of datagrams held for unreachable hosts) is dropped as if
/// lost on the wire: best-effort samples are lost, reliable ones resent. Without it a write on
/// the sensor path blocked 2.65 s when a host with two unreachable neighbours was cut off.
void make_udp_sends_non_blocking(eprosima::fastdds::dds::DomainParticipantQos& qos);

/// The one participant factory of every poise process, tools included: the QoS of `options`'
/// participant profile (QoS file loaded first), its name, non-blocking UDP sends
/// (make_udp_sends_non_blocking), DDS Security from the environment
/// (security_from_env()) and the discovery setup (a Discovery Server client from
/// ROS_DISCOVERY_SERVER or the profile; SUPER_CLIENT for ParticipantRole::kObserver).
/// Throws DdsError with what to fix (unknown profile, bad ROS_DISCOVERY_SERVER, missing files).
eprosima::fastdds::dds::DomainParticipantQos participant_qos(const ParticipantOptions& options);

/// The discovery setup participant_qos() chose, for messages: "simple (multicast)",
/// "client of 1 discovery server(s)", "super client of 2 discovery server(s)", ...
std::string describe_discovery(const eprosima::fastdds::dds::DomainParticipantQos& qos);

/// Creates a participant with participant_qos(options) (the listener, if any, is installed at
/// creation so no discovery event is missed). Throws DdsError naming the domain, profile,
/// discovery setup and, with security on, the identity and which of its files failed to verify.
eprosima::fastdds::dds::DomainParticipant* create_participant(
    const ParticipantOptions& options,
    eprosima::fastdds::dds::DomainParticipantListener* listener = nullptr,
    const eprosima::fastdds::dds::StatusMask& mask = eprosima::fastdds::dds::StatusMask::none());

/// A writer seen on a topic that this participant reads, with another type: its samples never
/// arrive (DDS matches endpoints by topic name AND type name), e.g. a ROS 2 driver's
/// `sensor_msgs::msg::dds_::Imu_` on a topic read as `poise::msg::ImuSample`.
struct TypeMismatch {
  std::string topic;
  std::string local_type;   ///< the type this participant reads the topic as
  std::string remote_type;  ///< the type of the remote writer
};

/// The warning printed once per (topic, remote type): names the topic and both types.
std::string describe(const TypeMismatch& mismatch);

/// One DomainParticipant with one Publisher and one Subscriber, and the topics created on it.
///
/// Type mismatches are loud: Fast DDS 2.9 does not report inconsistent topics
/// (on_inconsistent_topic is never called), so the participant watches the built-in publication
/// discovery and, for every topic one of its Readers reads, warns once per remote type that
/// differs (stderr, or the sink set by set_warning_sink) and keeps the list (type_mismatches()).
class Participant {
 public:
  explicit Participant(const ParticipantOptions& options);
  ~Participant();
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;

  [[nodiscard]] eprosima::fastdds::dds::DomainParticipant* get() const { return participant_; }
  [[nodiscard]] eprosima::fastdds::dds::Publisher* publisher() const { return publisher_; }
  [[nodiscard]] eprosima::fastdds::dds::Subscriber* subscriber() const { return subscriber_; }
  [[nodiscard]] int domain() const { return domain_; }
  /// The DDS Security identity in use (nullopt: security off).
  [[nodiscard]] const std::optional<SecurityConfig>& security() const { return security_; }

  /// The topic `name` of type `type`, registering the type and creating the topic on first use.
  /// Throws DdsError if the name is already used with another type.
  eprosima::fastdds::dds::Topic* topic(const std::string& name,
                                       const eprosima::fastdds::dds::TypeSupport& type);

  /// Records that a reader of this participant reads `topic` as `type` (Reader does it), so that
  /// writers of another type on that topic, seen before or after, are reported.
  void note_reader(const std::string& topic, const std::string& type);
  /// Every mismatch seen so far, one per (topic, remote type), in the order they were seen.
  [[nodiscard]] std::vector<TypeMismatch> type_mismatches() const;
  /// Where mismatch warnings go (default: one line on stderr). Called from a Fast DDS thread.
  void set_warning_sink(std::function<void(const std::string&)> sink);

 private:
  class DiscoveryWatch;
  std::unique_ptr<DiscoveryWatch> watch_;
  int domain_;
  std::optional<SecurityConfig> security_;
  eprosima::fastdds::dds::DomainParticipant* participant_ = nullptr;
  eprosima::fastdds::dds::Publisher* publisher_ = nullptr;
  eprosima::fastdds::dds::Subscriber* subscriber_ = nullptr;
  std::mutex mutex_;
  std::map<std::string, eprosima::fastdds::dds::Topic*> topics_;
};

namespace detail {
/// Creates a writer/reader from the endpoint profile of `kind`; throws DdsError on failure.
eprosima::fastdds::dds::DataWriter* create_writer(Participant& participant,
                                                  eprosima::fastdds::dds::Topic* topic,
                                                  QosKind kind,
                                                  eprosima::fastdds::dds::DataWriterListener* listener);
eprosima::fastdds::dds::DataReader* create_reader(Participant& participant,
                                                  eprosima::fastdds::dds::Topic* topic,
                                                  QosKind kind,
                                                  eprosima::fastdds::dds::DataReaderListener* listener);

/// Counts matched remote endpoints.
class MatchCounter : public eprosima::fastdds::dds::DataWriterListener,
                     public eprosima::fastdds::dds::DataReaderListener {
 public:
  void on_publication_matched(eprosima::fastdds::dds::DataWriter* writer,
                              const eprosima::fastdds::dds::PublicationMatchedStatus& info) override;
  void on_subscription_matched(eprosima::fastdds::dds::DataReader* reader,
                               const eprosima::fastdds::dds::SubscriptionMatchedStatus& info) override;
  [[nodiscard]] int matched() const { return matched_.load(); }

 private:
  std::atomic<int> matched_{0};
};

/// Polls `matched()` until it reaches `count` or the timeout elapses.
bool wait_matched(const MatchCounter& counter, int count, std::chrono::milliseconds timeout);

/// Generated type support made safe for untrusted bytes. fastddsgen 2.3's deserialize() lets
/// fastcdr's BadParamException (e.g. an unknown encapsulation) escape on a Fast DDS thread
/// (std::terminate), and a keyed change whose getKey() fails aborts the process in Fast DDS 2.9's
/// reader history. Here deserialize() and getKey() never throw, getKey() never fails (an
/// undecodable key is undecodable_instance()), and failed deserialize() calls are counted per data
/// object, so that Reader counts the samples Fast DDS then skips (Reader::malformed()) and drops
/// one it would hand over half-filled.
template <class PubSubType>
class GuardedType : public PubSubType {
 public:
  bool deserialize(eprosima::fastrtps::rtps::SerializedPayload_t* payload, void* data) override {
    bool ok = false;
    try {
      ok = payload != nullptr && PubSubType::deserialize(payload, data);
    } catch (...) {
      ok = false;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    Failures& f = failures_[data];
    f.last_failed = !ok;
    f.count += ok ? 0 : 1;
    return ok;
  }
  bool getKey(void* data, eprosima::fastrtps::rtps::InstanceHandle_t* handle,
              bool force_md5 = false) override {
    if (!this->m_isGetKeyDefined) {
      return false;
    }
    try {
      if (PubSubType::getKey(data, handle, force_md5)) {
        return true;
      }
    } catch (...) {
    }
    *handle = undecodable_instance();
    return true;
  }
  /// True when the last deserialize() into `data` failed.
  bool last_failed(const void* data) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = failures_.find(data);
    return it != failures_.end() && it->second.last_failed;
  }
  /// Failed deserialize() calls into `data` since the last call (then forgets `data`).
  uint64_t take_failures(const void* data) {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = failures_.find(data);
    if (it == failures_.end()) {
      return 0;
    }
    const uint64_t n = it->second.count;
    failures_.erase(it);
    return n;
  }

 private:
  struct Failures {
    uint64_t count = 0;
    bool last_failed = false;
  };
  std::mutex mutex_;
  std::map<const void*, Failures> failures_;
};
}  // namespace detail

/// A typed data writer. `PubSubType` is a fastddsgen-generated `XPubSubType`.
template <class PubSubType>
class Writer {
 public:
  using Message = typename PubSubType::type;

  Writer(Participant& participant, const std::string& topic_name, QosKind kind)
      : participant_(participant), topic_name_(topic_name) {
    topic_ = participant.topic(topic_name, eprosima::fastdds::dds::TypeSupport(
                                               new detail::GuardedType<PubSubType>()));
    writer_ = detail::create_writer(participant, topic_, kind, &listener_);
  }
  Writer(Participant& participant, const std::string& topic_name)
      : Writer(participant, topic_name, default_qos_for_topic(topic_name)) {}
  ~Writer() {
    if (writer_ != nullptr) {
      writer_->set_listener(nullptr);
      participant_.publisher()->delete_datawriter(writer_);
    }
  }
  Writer(const Writer&) = delete;
  Writer& operator=(const Writer&) = delete;

  /// Publishes one sample; false if Fast DDS refused it (e.g. history full with a reliable reader).
  bool write(const Message& message) {
    return writer_->write(const_cast<Message*>(&message));
  }
  [[nodiscard]] int matched() const { return listener_.matched(); }
  /// Waits (bounded) until at least `count` readers are matched.
  bool wait_for_readers(int count, std::chrono::milliseconds timeout) const {
    return detail::wait_matched(listener_, count, timeout);
  }
  [[nodiscard]] const std::string& topic_name() const { return topic_name_; }

 private:
  Participant& participant_;
  std::string topic_name_;
  eprosima::fastdds::dds::Topic* topic_ = nullptr;
  detail::MatchCounter listener_;
  eprosima::fastdds::dds::DataWriter* writer_ = nullptr;
};

/// A typed data reader calling `callback` for every valid sample, from a Fast DDS thread.
template <class PubSubType>
class Reader {
 public:
  using Message = typename PubSubType::type;
  using Callback = std::function<void(const Message&, const eprosima::fastdds::dds::SampleInfo&)>;

  /// `malformed` (optional, must outlive the reader): also counts the samples malformed() counts,
  /// for an owner that reports them after the reader is gone.
  Reader(Participant& participant, const std::string& topic_name, QosKind kind, Callback callback,
         std::atomic<uint64_t>* malformed = nullptr)
      : participant_(participant), listener_(std::move(callback), malformed) {
    topic_ = participant.topic(topic_name, eprosima::fastdds::dds::TypeSupport(
                                               new detail::GuardedType<PubSubType>()));
    // The type registered first under this name is the one Fast DDS uses (poise registers the
    // guarded type everywhere; a raw or foreign registration leaves failures undetected here).
    listener_.guard = dynamic_cast<detail::GuardedType<PubSubType>*>(
        participant.get()->find_type(topic_->get_type_name()).get());
    participant.note_reader(topic_name, topic_->get_type_name());  // type mismatches are loud
    reader_ = detail::create_reader(participant, topic_, kind, &listener_);
  }
  Reader(Participant& participant, const std::string& topic_name, Callback callback)
      : Reader(participant, topic_name, default_qos_for_topic(topic_name), std::move(callback)) {}
  ~Reader() {
    if (reader_ != nullptr) {
      reader_->set_listener(nullptr);
      participant_.subscriber()->delete_datareader(reader_);
    }
  }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  [[nodiscard]] int matched() const { return listener_.matched(); }
  bool wait_for_writers(int count, std::chrono::milliseconds timeout) const {
    return detail::wait_matched(listener_, count, timeout);
  }
  /// Samples delivered to the callback so far.
  [[nodiscard]] uint64_t received() const { return listener_.received(); }
  /// Samples dropped because their bytes did not deserialize (malformed, from any participant).
  [[nodiscard]] uint64_t malformed() const { return listener_.malformed(); }

 private:
  class Listener : public detail::MatchCounter {
   public:
    Listener(Callback callback, std::atomic<uint64_t>* malformed)
        : callback_(std::move(callback)), external_malformed_(malformed) {}
    void on_data_available(eprosima::fastdds::dds::DataReader* reader) override {
      Message message;
      eprosima::fastdds::dds::SampleInfo info;
      while (reader->take_next_sample(&message, &info) == ReturnCode::RETCODE_OK) {
        if (!info.valid_data || (guard != nullptr && guard->last_failed(&message))) {
          continue;  // a failed deserialize is counted below
        }
        received_.fetch_add(1);
        callback_(message, info);
      }
      // Samples whose bytes did not deserialize: Fast DDS skips them (or, above, we do).
      const uint64_t failed = guard != nullptr ? guard->take_failures(&message) : 0;
      malformed_.fetch_add(failed);
      if (external_malformed_ != nullptr) {
        external_malformed_->fetch_add(failed);
      }
    }
    [[nodiscard]] uint64_t received() const { return received_.load(); }
    [[nodiscard]] uint64_t malformed() const { return malformed_.load(); }
    detail::GuardedType<PubSubType>* guard = nullptr;  // set before the reader exists

   private:
    using ReturnCode = eprosima::fastrtps::types::ReturnCode_t;
    Callback callback_;
    std::atomic<uint64_t>* external_malformed_;
    std::atomic<uint64_t> received_{0};
    std::atomic<uint64_t> malformed_{0};
  };

  Participant& participant_;
  eprosima::fastdds::dds::Topic* topic_ = nullptr;
  Listener listener_;
  eprosima::fastdds::dds::DataReader* reader_ = nullptr;
};

}  // namespace poise::dds
