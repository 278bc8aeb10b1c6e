#include "netlab.h"

#include <sched.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <ctime>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace poise::nettest {
namespace {

constexpr const char* kPrefix = "poisenet";
constexpr auto kCommandTimeout = std::chrono::seconds(10);

std::string ip_binary() {
  for (const char* candidate : {"/usr/sbin/ip", "/sbin/ip", "/usr/bin/ip", "/bin/ip"}) {
    if (::access(candidate, X_OK) == 0) {
      return candidate;
    }
  }
  return {};
}

/// Runs `ip ARGS`; throws with the output on failure.
std::string ip_cmd(const std::vector<std::string>& args) {
  std::vector<std::string> argv{ip_binary()};
  argv.insert(argv.end(), args.begin(), args.end());
  const testing::RunResult r = testing::run(argv, kCommandTimeout);
  if (r.exit_code != 0) {
    std::string line;
    for (const auto& a : argv) {
      line += a + " ";
    }
    throw std::runtime_error("NetLab: `" + line + "` failed (" + std::to_string(r.exit_code) +
                             "): " + r.output);
  }
  return r.output;
}

/// Kills every process in namespace `ns` and deletes it; never throws.
void remove_namespace(const std::string& ns) noexcept {
  try {
    const testing::RunResult pids = testing::run({ip_binary(), "netns", "pids", ns}, kCommandTimeout);
    std::istringstream in(pids.output);
    long pid = 0;
    while (in >> pid) {
      if (pid > 1) {
        ::kill(static_cast<pid_t>(pid), SIGKILL);
      }
    }
    testing::run({ip_binary(), "netns", "del", ns}, kCommandTimeout);
  } catch (...) {
  }
}

}  // namespace

int64_t monotonic_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

std::string netlab_unavailable_reason() {
  if (::geteuid() != 0) {
    return "needs root to create network namespaces (CI runs the suite as root; run "
           "`sudo ctest -L network` to include these tests)";
  }
  if (ip_binary().empty()) {
    return "the `ip` command (iproute2) is not installed";
  }
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::_exit(::unshare(CLONE_NEWNET) == 0 ? 0 : 1);
  }
  int status = 0;
  if (pid < 0 || ::waitpid(pid, &status, 0) != pid || !WIFEXITED(status) ||
      WEXITSTATUS(status) != 0) {
    return "this environment does not allow new network namespaces (container without "
           "CAP_SYS_ADMIN?)";
  }
  return {};
}

void NetLab::sweep_stale() {
  const testing::RunResult list = testing::run({ip_binary(), "netns", "list"}, kCommandTimeout);
  std::istringstream in(list.output);
  std::string line;
  while (std::getline(in, line)) {
    const std::string name = line.substr(0, line.find(' '));
    if (name.rfind(kPrefix, 0) != 0) {
      continue;
    }
    const std::string digits = name.substr(std::string(kPrefix).size(),
                                           name.find('-') - std::string(kPrefix).size());
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos) {
      continue;
    }
    const auto owner = static_cast<pid_t>(std::stol(digits));
    if (::kill(owner, 0) != 0 && errno == ESRCH) {
      remove_namespace(name);
    }
  }
}

NetLab::NetLab(const std::vector<std::string>& hosts, bool multicast) : hosts_(hosts) {
  static int counter = 0;
  sweep_stale();
  prefix_ = std::string(kPrefix) + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  if (hosts.empty() || hosts.size() > 200) {
    throw std::invalid_argument("NetLab: 1 to 200 hosts");
  }
  try {
    const std::string sw = prefix_ + "-switch";
    ip_cmd({"netns", "add", sw});
    created_.push_back(sw);
    ip_cmd({"-n", sw, "link", "set", "lo", "up"});
    // No multicast snooping: the bridge floods multicast like a plain switch.
    ip_cmd({"-n", sw, "link", "add", "br0", "type", "bridge", "mcast_snooping", "0"});
    ip_cmd({"-n", sw, "link", "set", "br0", "up"});
    for (size_t i = 0; i < hosts.size(); ++i) {
      const std::string h = ns(hosts[i]);
      ip_cmd({"netns", "add", h});
      created_.push_back(h);
      const std::string port = "p" + std::to_string(i);
      ip_cmd({"link", "add", "name", port, "netns", sw, "type", "veth", "peer", "name", "eth0",
              "netns", h});
      ip_cmd({"-n", sw, "link", "set", port, "master", "br0", "up"});
      if (!multicast) {
        // A switch that drops multicast (as many managed / Wi-Fi networks do): the bridge port
        // does not flood multicast frames; broadcast (ARP) and unicast still pass.
        ip_cmd({"-n", sw, "link", "set", port, "type", "bridge_slave", "mcast_flood", "off"});
      }
      ip_cmd({"-n", h, "link", "set", "lo", "up"});
      ip_cmd({"-n", h, "addr", "add", ip(hosts[i]) + "/24", "dev", "eth0"});
      ip_cmd({"-n", h, "link", "set", "eth0", "multicast", multicast ? "on" : "off", "up"});
      if (multicast) {
        ip_cmd({"-n", h, "route", "add", "224.0.0.0/4", "dev", "eth0"});
      }
    }
  } catch (...) {
    cleanup();
    throw;
  }
}

NetLab::~NetLab() { cleanup(); }

void NetLab::cleanup() noexcept {
  for (auto it = created_.rbegin(); it != created_.rend(); ++it) {
    remove_namespace(*it);
  }
  created_.clear();
}

std::string NetLab::ns(const std::string& host) const { return prefix_ + "-" + host; }

std::string NetLab::ip(const std::string& host) const {
  for (size_t i = 0; i < hosts_.size(); ++i) {
    if (hosts_[i] == host) {
      return "10.77.0." + std::to_string(i + 1);
    }
  }
  throw std::invalid_argument("NetLab: no host " + host);
}

std::vector<std::string> NetLab::in_host(const std::string& host,
                                         const std::vector<std::string>& argv) const {
  static_cast<void>(ip(host));  // validates the name
  std::vector<std::string> out{ip_binary(), "netns", "exec", ns(host)};
  out.insert(out.end(), argv.begin(), argv.end());
  return out;
}

std::unique_ptr<testing::Child> NetLab::node(const std::string& host,
                                             const std::vector<std::string>& args,
                                             const std::vector<std::string>& env) const {
  std::vector<std::string> argv{testing::bin("poise_net_node")};
  argv.insert(argv.end(), args.begin(), args.end());
  return process(host, argv, env);
}

std::unique_ptr<testing::Child> NetLab::process(const std::string& host,
                                                const std::vector<std::string>& argv,
                                                const std::vector<std::string>& env) const {
  std::vector<std::string> full_env{"POISE_DDS_PROFILE=poise_udp"};
  full_env.insert(full_env.end(), env.begin(), env.end());
  return std::make_unique<testing::Child>(in_host(host, argv), full_env);
}

void NetLab::set_link(const std::string& host, bool up) const {
  for (size_t i = 0; i < hosts_.size(); ++i) {
    if (hosts_[i] == host) {
      ip_cmd({"-n", prefix_ + "-switch", "link", "set", "p" + std::to_string(i), up ? "up" : "down"});
      return;
    }
  }
  throw std::invalid_argument("NetLab: no host " + host);
}

TempDir::TempDir(const std::string& prefix)
    : path("/tmp/" + prefix + "-" + std::to_string(::getpid())),
      ok(testing::run({"/bin/mkdir", "-p", path}, kCommandTimeout).exit_code == 0) {}

TempDir::~TempDir() { testing::run({"/bin/rm", "-rf", path}, kCommandTimeout); }

RemoveOnExit::~RemoveOnExit() {
  if (!path.empty()) {
    ::unlink(path.c_str());
  }
}

std::string write_discovery_client_xml(const std::string& server_ip) {
  std::ifstream in(testing::source_path("config/qos/discovery_server_client.xml"));
  std::stringstream ss;
  ss << in.rdbuf();
  std::string xml = ss.str();
  const std::string placeholder = "192.168.1.10";
  for (size_t at = xml.find(placeholder); at != std::string::npos; at = xml.find(placeholder)) {
    xml.replace(at, placeholder.size(), server_ip);
  }
  static int count = 0;
  const std::string path = "/tmp/poise-ds-client-" + std::to_string(::getpid()) + "-" +
                           std::to_string(count++) + ".xml";
  std::ofstream(path) << xml;
  return path;
}

std::string discovery_server_binary() {
  for (const char* c : {"/usr/bin/fast-discovery-server", "/usr/local/bin/fast-discovery-server"}) {
    if (::access(c, X_OK) == 0) {
      return c;
    }
  }
  return {};
}

std::string Event::str(const std::string& key) const {
  const auto it = fields.find(key);
  return it == fields.end() ? std::string() : it->second;
}

double Event::num(const std::string& key) const {
  const auto it = fields.find(key);
  if (it == fields.end()) {
    throw std::runtime_error("event @" + name + " has no field " + key);
  }
  return std::stod(it->second);
}

std::vector<Event> parse_events(const std::string& output) {
  std::vector<Event> events;
  std::istringstream in(output);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] != '@') {
      continue;
    }
    Event e;
    std::istringstream words(line.substr(1));
    words >> e.name;
    std::string word;
    while (words >> word) {
      const size_t eq = word.find('=');
      if (eq != std::string::npos) {
        e.fields[word.substr(0, eq)] = word.substr(eq + 1);
      }
    }
    events.push_back(std::move(e));
  }
  return events;
}

std::vector<Event> find_events(const std::string& output, const std::string& name,
                               const std::map<std::string, std::string>& match) {
  std::vector<Event> out;
  for (auto& e : parse_events(output)) {
    bool ok = e.name == name;
    for (const auto& [k, v] : match) {
      ok = ok && e.str(k) == v;
    }
    if (ok) {
      out.push_back(std::move(e));
    }
  }
  return out;
}

std::optional<Event> wait_event(const testing::Child& child, const std::string& name,
                                const std::map<std::string, std::string>& match,
                                std::chrono::milliseconds timeout, int64_t after_ns) {
  std::optional<Event> found;
  testing::wait_until(
      [&] {
        for (auto& e : find_events(child.output(), name, match)) {
          if (after_ns <= 0 || (e.fields.count("t_ns") != 0 && e.num("t_ns") >= static_cast<double>(after_ns))) {
            found = std::move(e);
            return true;
          }
        }
        return false;
      },
      timeout);
  return found;
}

void stop(testing::Child& child) {
  child.signal(SIGINT);
  if (!child.wait_for(std::chrono::seconds(10))) {
    child.signal(SIGKILL);
    child.wait_for(std::chrono::seconds(5));
  }
}

std::string cyclone_loopback_config() {
  return "CYCLONEDDS_URI=<CycloneDDS><Domain Id=\"any\"><General><Interfaces>"
         "<NetworkInterface name=\"lo\"/></Interfaces><AllowMulticast>false</AllowMulticast>"
         "</General><Discovery><ParticipantIndex>auto</ParticipantIndex><Peers>"
         "<Peer address=\"127.0.0.1\"/></Peers></Discovery></Domain></CycloneDDS>";
}

std::vector<double> split_doubles(const std::string& list) {
  std::vector<double> out;
  std::istringstream in(list);
  std::string item;
  while (std::getline(in, item, ',')) {
    out.push_back(std::stod(item));
  }
  return out;
}

}  // namespace poise::nettest
