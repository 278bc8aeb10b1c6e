#include "poise/dds/participant.h"

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/rtps/attributes/ServerAttributes.h>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/UDPv6TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <set>
#include <thread>

namespace poise::dds {
namespace detail {
extern const char* const kEmbeddedProfiles;
}

namespace fdds = eprosima::fastdds::dds;
using eprosima::fastrtps::types::ReturnCode_t;

namespace {
std::string env_or(const char* name, const std::string& fallback) {
  const char* value = std::getenv(name);
  return (value != nullptr && *value != '\0') ? std::string(value) : fallback;
}
}  // namespace

void load_profiles(const std::string& qos_file) {
  static std::mutex mutex;
  static std::set<std::string> loaded;
  const std::string file = qos_file.empty() ? env_or("POISE_QOS_FILE", "") : qos_file;
  std::lock_guard<std::mutex> lock(mutex);
  if (loaded.count(file) != 0) {
    return;
  }
  auto* factory = fdds::DomainParticipantFactory::get_instance();
  if (file.empty()) {
    const char* xml = detail::kEmbeddedProfiles;
    if (factory->load_XML_profiles_string(xml, std::strlen(xml)) != ReturnCode_t::RETCODE_OK) {
      throw DdsError("the built-in QoS profiles failed to load (a build defect)");
    }
  } else {
    if (!std::ifstream(file).good()) {
      throw DdsError("QoS profiles file '" + file + "' cannot be read (check POISE_QOS_FILE)");
    }
    if (factory->load_XML_profiles_file(file) != ReturnCode_t::RETCODE_OK) {
      throw DdsError("QoS profiles file '" + file + "' is not a valid Fast DDS XML profiles file");
    }
  }
  loaded.insert(file);
}

std::optional<SecurityConfig> security_from_env() {
  const std::string dir = env_or("POISE_SECURITY_DIR", "");
  if (dir.empty()) {
    return std::nullopt;
  }
  const std::string identity = env_or("POISE_SECURITY_IDENTITY", "");
  if (identity.empty()) {
    throw DdsError("POISE_SECURITY_DIR is set but POISE_SECURITY_IDENTITY is not: set it to the "
                   "identity (host name) to use from " + dir);
  }
  return SecurityConfig{dir, identity};
}

std::vector<std::pair<std::string, std::string>> security_properties(const SecurityConfig& config) {
  if (config.identity.empty() || config.identity.find('/') != std::string::npos) {
    throw DdsError("invalid security identity '" + config.identity + "' (a host name from " +
                   config.dir + ")");
  }
  const std::string ca = config.dir + "/ca.pem";
  const std::string governance = config.dir + "/governance.p7s";
  const std::string id_dir = config.dir + "/" + config.identity;
  const std::string cert = id_dir + "/cert.pem";
  const std::string key = id_dir + "/key.pem";
  const std::string permissions = id_dir + "/permissions.p7s";
  for (const std::string& file : {ca, governance, cert, key, permissions}) {
    if (!std::ifstream(file).good()) {
      throw DdsError("DDS Security file '" + file + "' is missing or unreadable (create the " +
                     "directory with tools/security/make_security.sh; identity '" +
                     config.identity + "')");
    }
  }
  const std::string auth = "dds.sec.auth.builtin.PKI-DH.";
  const std::string access = "dds.sec.access.builtin.Access-Permissions.";
  return {
      {"dds.sec.auth.plugin", "builtin.PKI-DH"},
      {auth + "identity_ca", "file://" + ca},
      {auth + "identity_certificate", "file://" + cert},
      {auth + "private_key", "file://" + key},
      {"dds.sec.access.plugin", "builtin.Access-Permissions"},
      {access + "permissions_ca", "file://" + ca},
      {access + "governance", "file://" + governance},
      {access + "permissions", "file://" + permissions},
      {"dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC"},
  };
}

std::string resolve_participant_profile(const ParticipantOptions& options) {
  return options.profile.empty() ? env_or("POISE_DDS_PROFILE", "poise_default") : options.profile;
}

namespace {
/// Why Fast DDS (which logs little) refused a secure participant, as far as can be told here.
std::string diagnose_security(const SecurityConfig& security, int domain) {
  const std::string problem = check_security_files(security, domain);
  return problem.empty() ? "its files verify here (certificate from the CA, key, signatures, "
                           "subject, domain): check that governance and permissions come from "
                           "the same CA as the other hosts"
                         : problem;
}
}  // namespace

void make_udp_sends_non_blocking(fdds::DomainParticipantQos& qos) {
  namespace rtps = eprosima::fastdds::rtps;
  auto& transport = qos.transport();
  if (transport.use_builtin_transports) {
    // Fast DDS 2.9's built-in transports, spelled out (RTPSParticipantImpl): UDPv4 with the
    // participant's socket buffer sizes, and shared memory with a segment of twice the larger.
    auto udp = std::make_shared<rtps::UDPv4TransportDescriptor>();
    udp->sendBufferSize = transport.send_socket_buffer_size;
    udp->receiveBufferSize = transport.listen_socket_buffer_size;
    auto shm = std::make_shared<rtps::SharedMemTransportDescriptor>();
    shm->segment_size(std::max(transport.send_socket_buffer_size, transport.listen_socket_buffer_size) * 2);
    shm->max_message_size(udp->max_message_size());
    transport.user_transports.insert(transport.user_transports.begin(), {udp, shm});
    transport.use_builtin_transports = false;
  }
  for (auto& descriptor : transport.user_transports) {
    // Copies: the descriptors are shared with the loaded XML profile.
    if (const auto* v4 = dynamic_cast<const rtps::UDPv4TransportDescriptor*>(descriptor.get())) {
      auto copy = std::make_shared<rtps::UDPv4TransportDescriptor>(*v4);
      copy->non_blocking_send = true;
      descriptor = copy;
    } else if (const auto* v6 = dynamic_cast<const rtps::UDPv6TransportDescriptor*>(descriptor.get())) {
      auto copy = std::make_shared<rtps::UDPv6TransportDescriptor>(*v6);
      copy->non_blocking_send = true;
      descriptor = copy;
    }
  }
}

fdds::DomainParticipantQos participant_qos(const ParticipantOptions& options) {
  load_profiles(options.qos_file);
  auto* factory = fdds::DomainParticipantFactory::get_instance();
  const std::string profile = resolve_participant_profile(options);
  fdds::DomainParticipantQos qos;
  if (factory->get_participant_qos_from_profile(profile, qos) != ReturnCode_t::RETCODE_OK) {
    throw DdsError("no participant profile '" + profile +
                   "' in the QoS profiles (known: poise_default, poise_udp, poise_loopback, and "
                   "those of config/qos/discovery_server_client.xml)");
  }
  qos.name(options.name);
  make_udp_sends_non_blocking(qos);
  const std::optional<SecurityConfig> security = security_from_env();
  if (security) {
    for (const auto& [name, value] : security_properties(*security)) {
      qos.properties().properties().emplace_back(name, value);
    }
  }
  using eprosima::fastrtps::rtps::DiscoveryProtocol_t;
  auto& discovery = qos.wire_protocol().builtin.discovery_config;
  const std::string servers = env_or("ROS_DISCOVERY_SERVER", "");
  if (discovery.discoveryProtocol == DiscoveryProtocol_t::SIMPLE && !servers.empty()) {
    // What Fast DDS would do with the variable, done here so that the role decides the kind.
    eprosima::fastdds::rtps::RemoteServerList_t list;
    if (!eprosima::fastdds::rtps::load_environment_server_info(servers, list) || list.empty()) {
      throw DdsError("ROS_DISCOVERY_SERVER='" + servers + "' is not a list of discovery servers "
                     "(IP:PORT, several separated by ';', position = server id)");
    }
    discovery.discoveryProtocol = DiscoveryProtocol_t::CLIENT;
    discovery.m_DiscoveryServers = list;
  }
  if (options.role == ParticipantRole::kObserver &&
      discovery.discoveryProtocol == DiscoveryProtocol_t::CLIENT) {
    // A plain client only learns about endpoints it matches: a tool that must see every topic
    // (before it has a reader for any) receives all discovery data as a super client.
    discovery.discoveryProtocol = DiscoveryProtocol_t::SUPER_CLIENT;
  }
  return qos;
}

std::string describe_discovery(const fdds::DomainParticipantQos& qos) {
  using eprosima::fastrtps::rtps::DiscoveryProtocol_t;
  const auto& discovery = qos.wire_protocol().builtin.discovery_config;
  const std::string n = std::to_string(discovery.m_DiscoveryServers.size());
  switch (discovery.discoveryProtocol) {
    case DiscoveryProtocol_t::SIMPLE: return "simple discovery (multicast)";
    case DiscoveryProtocol_t::CLIENT: return "client of " + n + " discovery server(s)";
    case DiscoveryProtocol_t::SUPER_CLIENT: return "super client of " + n + " discovery server(s)";
    case DiscoveryProtocol_t::SERVER: return "discovery server";
    case DiscoveryProtocol_t::BACKUP: return "discovery server (backup)";
    default: return "static or no discovery";
  }
}

fdds::DomainParticipant* create_participant(const ParticipantOptions& options,
                                            fdds::DomainParticipantListener* listener,
                                            const fdds::StatusMask& mask) {
  if (options.domain < 0 || options.domain > 232) {
    throw DdsError("domain " + std::to_string(options.domain) +
                   " is impossible: DDS over UDP uses ports 7400 + 250 * domain + offsets, which "
                   "leave the 16-bit port range above domain 232 (use 0..232)");
  }
  const fdds::DomainParticipantQos qos = participant_qos(options);
  fdds::DomainParticipant* participant = fdds::DomainParticipantFactory::get_instance()->create_participant(
      static_cast<fdds::DomainId_t>(options.domain), qos, listener, mask);
  if (participant == nullptr) {
    const std::optional<SecurityConfig> security = security_from_env();
    throw DdsError("cannot create a DDS participant on domain " + std::to_string(options.domain) +
                   " with profile '" + resolve_participant_profile(options) + "' (" +
                   describe_discovery(qos) + ")" +
                   (security ? "; DDS Security identity '" + security->identity + "' of " +
                                   security->dir + ": " + diagnose_security(*security, options.domain)
                             : std::string()));
  }
  return participant;
}

std::string describe(const TypeMismatch& m) {
  std::string hint;
  if (m.remote_type.find("::dds_::") != std::string::npos) {
    hint = "; a ROS 2 type: bridge it with the ros2_bridge component (docs/ROS2.md)";
  }
  return "poise: warning: topic '" + m.topic + "' has a writer of type '" + m.remote_type +
         "' but this process reads it as '" + m.local_type +
         "': DDS never delivers its samples here (the types must be the same)" + hint;
}

/// Watches the built-in publication discovery for writers whose type differs from the type our
/// readers use on the same topic name (Fast DDS 2.9 has no inconsistent-topic status).
class Participant::DiscoveryWatch : public fdds::DomainParticipantListener {
 public:
  void on_publisher_discovery(fdds::DomainParticipant* /*participant*/,
                              eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) override {
    if (info.status != eprosima::fastrtps::rtps::WriterDiscoveryInfo::DISCOVERED_WRITER) {
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    const std::string topic = info.info.topicName().to_string();
    const std::string type = info.info.typeName().to_string();
    writers_[topic].insert(type);
    check(topic);
  }
  void note_reader(const std::string& topic, const std::string& type) {
    std::lock_guard<std::mutex> lock(mutex_);
    readers_[topic] = type;
    check(topic);
  }
  std::vector<TypeMismatch> mismatches() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return mismatches_;
  }
  void set_sink(std::function<void(const std::string&)> sink) {
    std::lock_guard<std::mutex> lock(mutex_);
    sink_ = std::move(sink);
  }

 private:
  /// Reports every new (topic, remote type) pair that differs from our reader's type.
  void check(const std::string& topic) {
    const auto reader = readers_.find(topic);
    const auto writers = writers_.find(topic);
    if (reader == readers_.end() || writers == writers_.end()) {
      return;
    }
    for (const std::string& type : writers->second) {
      if (type == reader->second || !warned_.insert({topic, type}).second) {
        continue;
      }
      mismatches_.push_back({topic, reader->second, type});
      const std::string line = describe(mismatches_.back());
      if (sink_) {
        sink_(line);
      } else {
        std::fprintf(stderr, "%s\n", line.c_str());
      }
    }
  }

  mutable std::mutex mutex_;
  std::map<std::string, std::string> readers_;                // topic -> our type
  std::map<std::string, std::set<std::string>> writers_;     // topic -> remote types seen
  std::set<std::pair<std::string, std::string>> warned_;      // (topic, remote type)
  std::vector<TypeMismatch> mismatches_;
  std::function<void(const std::string&)> sink_;
};

void Participant::note_reader(const std::string& topic, const std::string& type) {
  watch_->note_reader(topic, type);
}

std::vector<TypeMismatch> Participant::type_mismatches() const { return watch_->mismatches(); }

void Participant::set_warning_sink(std::function<void(const std::string&)> sink) {
  watch_->set_sink(std::move(sink));
}

Participant::Participant(const ParticipantOptions& options)
    : watch_(std::make_unique<DiscoveryWatch>()), domain_(options.domain), security_(security_from_env()) {
  // The watch is installed at creation so that no publication discovery is missed; no status
  // mask: entity statuses stay with the entities' own listeners.
  participant_ = create_participant(options, watch_.get(), fdds::StatusMask::none());
  publisher_ = participant_->create_publisher(fdds::PUBLISHER_QOS_DEFAULT);
  subscriber_ = participant_->create_subscriber(fdds::SUBSCRIBER_QOS_DEFAULT);
  if (publisher_ == nullptr || subscriber_ == nullptr) {
    participant_->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant_);
    throw DdsError("cannot create the DDS publisher/subscriber");
  }
}

Participant::~Participant() {
  if (participant_ != nullptr) {
    participant_->delete_contained_entities();
    fdds::DomainParticipantFactory::get_instance()->delete_participant(participant_);
  }
}

eprosima::fastrtps::rtps::InstanceHandle_t undecodable_instance() {
  eprosima::fastrtps::rtps::InstanceHandle_t handle;
  for (std::size_t k = 0; k < 16; ++k) {
    handle.value[k] = 0xFF;
  }
  return handle;
}

fdds::Topic* Participant::topic(const std::string& name, const fdds::TypeSupport& type) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto found = topics_.find(name);
  if (found != topics_.end()) {
    if (found->second->get_type_name() != type.get_type_name()) {
      throw DdsError("topic '" + name + "' is already used with type " +
                     found->second->get_type_name() + ", not " + type.get_type_name());
    }
    return found->second;
  }
  fdds::TypeSupport registered = participant_->find_type(type.get_type_name());
  if (registered.empty()) {
    fdds::TypeSupport copy = type;
    if (copy.register_type(participant_) != ReturnCode_t::RETCODE_OK) {
      throw DdsError("cannot register DDS type " + type.get_type_name());
    }
  }
  fdds::Topic* topic = participant_->create_topic(name, type.get_type_name(), fdds::TOPIC_QOS_DEFAULT);
  if (topic == nullptr) {
    throw DdsError("cannot create DDS topic '" + name + "' (type " + type.get_type_name() + ")");
  }
  topics_[name] = topic;
  return topic;
}

namespace detail {
namespace {
/// Why an endpoint was refused: the profile is missing, or (security on, profile fine) access
/// control: Fast DDS refuses the endpoint when the permissions do not grant the topic.
std::string refusal(const Participant& participant, bool profile_ok, const char* action,
                    const std::string& topic) {
  if (!profile_ok) {
    return ": no such endpoint profile in the QoS profiles";
  }
  const auto& security = participant.security();
  if (!security) {
    return {};
  }
  return ": refused by DDS Security access control: the permissions of identity '" +
         security->identity + "' (" + security->dir + "/" + security->identity +
         "/permissions.xml) have no grant to " + action + " '" + topic + "' on domain " +
         std::to_string(participant.domain()) +
         " (add the topic to its rules in tools/security/make_security.sh and sign again)";
}
}  // namespace

fdds::DataWriter* create_writer(Participant& participant, fdds::Topic* topic, QosKind kind,
                                fdds::DataWriterListener* listener) {
  fdds::DataWriter* writer = participant.publisher()->create_datawriter_with_profile(
      topic, profile_name(kind), listener, fdds::StatusMask::publication_matched());
  if (writer == nullptr) {
    fdds::DataWriterQos qos;
    const bool profile_ok = participant.publisher()->get_datawriter_qos_from_profile(
                                profile_name(kind), qos) == ReturnCode_t::RETCODE_OK;
    throw DdsError("cannot create a DDS writer on '" + topic->get_name() + "' with profile '" +
                   profile_name(kind) + "'" + refusal(participant, profile_ok, "publish", topic->get_name()));
  }
  return writer;
}

fdds::DataReader* create_reader(Participant& participant, fdds::Topic* topic, QosKind kind,
                                fdds::DataReaderListener* listener) {
  fdds::DataReader* reader = participant.subscriber()->create_datareader_with_profile(
      topic, profile_name(kind), listener,
      fdds::StatusMask::data_available() << fdds::StatusMask::subscription_matched());
  if (reader == nullptr) {
    fdds::DataReaderQos qos;
    const bool profile_ok = participant.subscriber()->get_datareader_qos_from_profile(
                                profile_name(kind), qos) == ReturnCode_t::RETCODE_OK;
    throw DdsError("cannot create a DDS reader on '" + topic->get_name() + "' with profile '" +
                   profile_name(kind) + "'" + refusal(participant, profile_ok, "subscribe", topic->get_name()));
  }
  return reader;
}

void MatchCounter::on_publication_matched(fdds::DataWriter* /*writer*/,
                                          const fdds::PublicationMatchedStatus& info) {
  matched_.store(info.current_count);
}

void MatchCounter::on_subscription_matched(fdds::DataReader* /*reader*/,
                                           const fdds::SubscriptionMatchedStatus& info) {
  matched_.store(info.current_count);
}

bool wait_matched(const MatchCounter& counter, int count, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (counter.matched() < count) {
    if (std::chrono::steady_clock::now() >= deadline) {
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return true;
}

}  // namespace detail
}  // namespace poise::dds
