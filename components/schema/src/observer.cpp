#include "poise/schema/observer.h"

#include "poise/dds/participant.h"
#include "poise/schema/cdr.h"

#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/subscriber/qos/SubscriberQos.hpp>
#include <fastdds/rtps/writer/WriterDiscoveryInfo.h>

#include <algorithm>
#include <atomic>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

namespace poise::schema {

namespace fdds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;
using eprosima::fastrtps::types::ReturnCode_t;

namespace {

class RawReaderListener : public fdds::DataReaderListener {
 public:
  // `table` null or not knowing `type`: payloads are passed on unchecked.
  RawReaderListener(const TypeTable* table, std::string type,
                    TopicObserver::SampleCallback callback, TopicObserver::RejectCallback rejected)
      : table_(table),
        type_(std::move(type)),
        callback_(std::move(callback)),
        rejected_(std::move(rejected)) {}
  void on_data_available(fdds::DataReader* reader) override {
    poise::dds::RawSample sample;
    fdds::SampleInfo info;
    while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
      if (!info.valid_data) {
        continue;
      }
      const std::optional<std::string> problem =
          table_ != nullptr ? payload_problem(*table_, type_, sample.data.data(), sample.data.size())
                            : std::nullopt;
      if (problem) {
        malformed_.fetch_add(1);
        if (rejected_) {
          rejected_(sample, info, *problem);
        }
        continue;
      }
      accepted_.fetch_add(1);
      if (callback_) {
        callback_(sample, info);
      }
    }
  }
  [[nodiscard]] TopicObserver::Counts counts() const { return {accepted_.load(), malformed_.load()}; }
  void on_subscription_matched(fdds::DataReader* /*reader*/,
                               const fdds::SubscriptionMatchedStatus& status) override {
    matched_.store(status.current_count);
  }
  [[nodiscard]] int matched() const { return matched_.load(); }

 private:
  const TypeTable* table_;
  std::string type_;
  TopicObserver::SampleCallback callback_;
  TopicObserver::RejectCallback rejected_;
  std::atomic<int> matched_{0};
  std::atomic<std::uint64_t> accepted_{0};
  std::atomic<std::uint64_t> malformed_{0};
};

}  // namespace

struct TopicObserver::Impl : public fdds::DomainParticipantListener {
  fdds::DomainParticipant* participant = nullptr;
  // Guards `alive` only. Never held while calling into Fast DDS: discovery callbacks run on Fast
  // DDS threads that may hold its internal locks, so nesting the two could deadlock.
  mutable std::mutex mutex;
  std::vector<DiscoveredWriter> alive;
  mutable std::mutex subscriptions_mutex;  // guards `subscriptions` (user threads only)

  struct Subscription {
    fdds::Subscriber* subscriber = nullptr;
    fdds::Topic* topic = nullptr;
    fdds::DataReader* reader = nullptr;
    std::unique_ptr<RawReaderListener> listener;
  };
  std::map<std::string, Subscription> subscriptions;  // by topic name

  void on_publisher_discovery(fdds::DomainParticipant* /*participant*/,
                              rtps::WriterDiscoveryInfo&& info) override {
    const rtps::WriterProxyData& data = info.info;
    std::ostringstream guid;
    guid << data.guid();
    std::lock_guard<std::mutex> lock(mutex);
    const auto it = std::find_if(alive.begin(), alive.end(),
                                 [&guid](const DiscoveredWriter& w) { return w.guid == guid.str(); });
    if (info.status == rtps::WriterDiscoveryInfo::REMOVED_WRITER) {
      if (it != alive.end()) {
        alive.erase(it);
      }
      return;
    }
    DiscoveredWriter w;
    w.guid = guid.str();
    w.topic = data.topicName().to_string();
    w.type = data.typeName().to_string();
    w.keyed = data.topicKind() == rtps::WITH_KEY;
    w.reliable = data.m_qos.m_reliability.kind == fdds::RELIABLE_RELIABILITY_QOS;
    w.transient_local = data.m_qos.m_durability.kind != fdds::VOLATILE_DURABILITY_QOS;
    w.exclusive_ownership = data.m_qos.m_ownership.kind == fdds::EXCLUSIVE_OWNERSHIP_QOS;
    w.partitions = data.m_qos.m_partition.names();
    w.max_serialized_size = data.typeMaxSerialized();
    if (it != alive.end()) {
      *it = std::move(w);  // CHANGED_QOS_WRITER (or a repeated announcement)
    } else {
      alive.push_back(std::move(w));
    }
  }
};

TopicObserver::TopicObserver(const ObserverOptions& options) : impl_(std::make_unique<Impl>()) {
  poise::dds::ParticipantOptions popts;
  popts.domain = options.domain;
  popts.profile = options.profile;
  popts.qos_file = options.qos_file;
  popts.name = options.name;
  popts.role = poise::dds::ParticipantRole::kObserver;  // sees every topic, also via a server
  // The listener is installed at creation so that no discovery event is missed.
  impl_->participant = poise::dds::create_participant(popts, impl_.get(), fdds::StatusMask::none());
}

TopicObserver::~TopicObserver() {
  if (impl_->participant == nullptr) {
    return;
  }
  for (auto& [name, sub] : impl_->subscriptions) {
    (void)name;
    sub.reader->set_listener(nullptr);
  }
  impl_->participant->set_listener(nullptr);
  impl_->participant->delete_contained_entities();
  fdds::DomainParticipantFactory::get_instance()->delete_participant(impl_->participant);
}

std::vector<DiscoveredWriter> TopicObserver::writers() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->alive;
}

std::optional<DiscoveredWriter> TopicObserver::wait_for_writer(
    const std::string& topic, std::chrono::milliseconds timeout,
    const std::function<bool()>& cancelled) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    {
      std::lock_guard<std::mutex> lock(impl_->mutex);
      for (const auto& w : impl_->alive) {
        if (w.topic == topic) {
          return w;
        }
      }
    }
    if (std::chrono::steady_clock::now() >= deadline || (cancelled && cancelled())) {
      return std::nullopt;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

void TopicObserver::subscribe(const DiscoveredWriter& writer, const TypeTable* table,
                              SampleCallback callback, const RawReaderOptions& options,
                              RejectCallback rejected) {
  std::lock_guard<std::mutex> lock(impl_->subscriptions_mutex);
  if (impl_->subscriptions.count(writer.topic) != 0) {
    throw poise::dds::DdsError("topic '" + writer.topic + "' is already subscribed");
  }
  fdds::DomainParticipant* p = impl_->participant;
  if (p->find_type(writer.type) == nullptr) {
    const std::uint32_t max_size = writer.max_serialized_size > 0
                                       ? writer.max_serialized_size
                                       : poise::dds::RawPubSubType::kDefaultMaxSize;
    // The reader's topic kind must equal the writer's or they never match: when a peer publishes a
    // known type name with a different keyed-ness (another IDL version), ignore the schema's key.
    const StructDef* schema = table != nullptr ? table->find_struct(writer.type) : nullptr;
    const TypeTable* key_table =
        (schema != nullptr && schema->has_key() != writer.keyed) ? nullptr : table;
    fdds::TypeSupport type(
        new poise::dds::RawPubSubType(writer.type, key_table, writer.keyed, max_size));
    if (type.register_type(p) != ReturnCode_t::RETCODE_OK) {
      throw poise::dds::DdsError("cannot register the raw type '" + writer.type + "'");
    }
  }
  Impl::Subscription sub;
  fdds::SubscriberQos sqos = fdds::SUBSCRIBER_QOS_DEFAULT;
  for (const auto& partition : writer.partitions) {
    sqos.partition().push_back(partition.c_str());
  }
  sub.subscriber = p->create_subscriber(sqos);
  sub.topic = p->create_topic(writer.topic, writer.type, fdds::TOPIC_QOS_DEFAULT);
  if (sub.subscriber == nullptr || sub.topic == nullptr) {
    throw poise::dds::DdsError("cannot create the topic '" + writer.topic + "' of type '" +
                               writer.type + "'");
  }
  fdds::DataReaderQos rqos = fdds::DATAREADER_QOS_DEFAULT;
  rqos.reliability().kind =
      options.reliable ? fdds::RELIABLE_RELIABILITY_QOS : fdds::BEST_EFFORT_RELIABILITY_QOS;
  rqos.durability().kind = options.transient_local ? fdds::TRANSIENT_LOCAL_DURABILITY_QOS
                                                   : fdds::VOLATILE_DURABILITY_QOS;
  rqos.history().kind = fdds::KEEP_LAST_HISTORY_QOS;
  rqos.history().depth = std::max(1, options.history_depth);
  rqos.ownership().kind = writer.exclusive_ownership ? fdds::EXCLUSIVE_OWNERSHIP_QOS
                                                     : fdds::SHARED_OWNERSHIP_QOS;
  sub.listener = std::make_unique<RawReaderListener>(table, writer.type, std::move(callback),
                                                     std::move(rejected));
  sub.reader = sub.subscriber->create_datareader(
      sub.topic, rqos, sub.listener.get(),
      fdds::StatusMask::data_available() << fdds::StatusMask::subscription_matched());
  if (sub.reader == nullptr) {
    throw poise::dds::DdsError("cannot create a raw reader on '" + writer.topic + "'");
  }
  impl_->subscriptions.emplace(writer.topic, std::move(sub));
}

TopicObserver::Counts TopicObserver::counts(const std::string& topic) const {
  std::lock_guard<std::mutex> lock(impl_->subscriptions_mutex);
  const auto it = impl_->subscriptions.find(topic);
  return it == impl_->subscriptions.end() ? Counts{} : it->second.listener->counts();
}

int TopicObserver::matched_writers(const std::string& topic) const {
  std::lock_guard<std::mutex> lock(impl_->subscriptions_mutex);
  const auto it = impl_->subscriptions.find(topic);
  return it == impl_->subscriptions.end() ? 0 : it->second.listener->matched();
}

}  // namespace poise::schema
