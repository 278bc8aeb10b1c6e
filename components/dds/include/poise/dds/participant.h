// RAII wrappers around Fast DDS entities (habit: entities created in the constructor, which throws
// on failure; delete_contained_entities() in the destructor). QoS comes from XML profiles.
#pragma once

#include "poise/dds/topics.h"

#include <fastdds/dds/core/status/StatusMask.hpp>
#include <fastdds/dds/domain/DomainParticipant.hpp>
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

struct ParticipantOptions {
  int domain = 0;
  /// Participant profile; empty: $POISE_DDS_PROFILE, else "poise_default".
  std::string profile;
  /// Profiles XML file; empty: $POISE_QOS_FILE, else the copy of config/qos/poise_profiles.xml
  /// built into the binary.
  std::string qos_file;
  /// Participant name shown to discovery tools.
  std::string name = "poise";
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

/// Loads the QoS profiles (once per process and file). Throws DdsError if the file is unreadable
/// or invalid. Called by Participant; call it yourself only to fail early.
void load_profiles(const std::string& qos_file = {});

/// The participant profile that `options` resolve to.
std::string resolve_participant_profile(const ParticipantOptions& options);

/// One DomainParticipant with one Publisher and one Subscriber, and the topics created on it.
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

  /// The topic `name` of type `type`, registering the type and creating the topic on first use.
  /// Throws DdsError if the name is already used with another type.
  eprosima::fastdds::dds::Topic* topic(const std::string& name,
                                       const eprosima::fastdds::dds::TypeSupport& type);

 private:
  int domain_;
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
}  // namespace detail

/// A typed data writer. `PubSubType` is a fastddsgen-generated `XPubSubType`.
template <class PubSubType>
class Writer {
 public:
  using Message = typename PubSubType::type;

  Writer(Participant& participant, const std::string& topic_name, QosKind kind)
      : participant_(participant), topic_name_(topic_name) {
    topic_ = participant.topic(topic_name, eprosima::fastdds::dds::TypeSupport(new PubSubType()));
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

  Reader(Participant& participant, const std::string& topic_name, QosKind kind, Callback callback)
      : participant_(participant), listener_(std::move(callback)) {
    topic_ = participant.topic(topic_name, eprosima::fastdds::dds::TypeSupport(new PubSubType()));
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

 private:
  class Listener : public detail::MatchCounter {
   public:
    explicit Listener(Callback callback) : callback_(std::move(callback)) {}
    void on_data_available(eprosima::fastdds::dds::DataReader* reader) override {
      Message message;
      eprosima::fastdds::dds::SampleInfo info;
      while (reader->take_next_sample(&message, &info) == ReturnCode::RETCODE_OK) {
        if (info.valid_data) {
          received_.fetch_add(1);
          callback_(message, info);
        }
      }
    }
    [[nodiscard]] uint64_t received() const { return received_.load(); }

   private:
    using ReturnCode = eprosima::fastrtps::types::ReturnCode_t;
    Callback callback_;
    std::atomic<uint64_t> received_{0};
  };

  Participant& participant_;
  eprosima::fastdds::dds::Topic* topic_ = nullptr;
  Listener listener_;
  eprosima::fastdds::dds::DataReader* reader_ = nullptr;
};

}  // namespace poise::dds
