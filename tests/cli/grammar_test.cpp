// GIVEN every `poise` subcommand (walked from `poise --help`, recursively) WHEN its --help is
// printed THEN the shared options have one name and one meaning (docs/TOOLS.md "Command grammar"),
// retired spellings are hidden, and a bad environment value never breaks --help.
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;

struct Option {
  std::string names;  // e.g. "-o,--output"
  std::string text;   // type and description
};

struct Help {
  int exit_code = 0;
  std::vector<std::string> subcommands;
  std::map<std::string, Option> options;  // by long name
};

Help help_of(const std::vector<std::string>& path) {
  std::vector<std::string> argv{bin("poise")};
  argv.insert(argv.end(), path.begin(), path.end());
  argv.emplace_back("--help");
  // A broken environment must not break --help.
  const RunResult r = run(argv, 30s, {"POISE_DOMAIN=abc"});
  Help h;
  h.exit_code = r.exit_code;
  std::istringstream in(r.output);
  std::string line;
  std::string section;
  static const std::regex option_re(R"(^  ((?:-\w,)?(--[\w-]+))\s*(.*)$)");
  static const std::regex sub_re(R"(^  ([a-z][\w-]*)\s{2,}.*$)");
  Option* last = nullptr;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == ':' && line[0] != ' ') {
      section = line;
      last = nullptr;
      continue;
    }
    std::smatch m;
    if (section == "Subcommands:" && std::regex_match(line, m, sub_re)) {
      h.subcommands.push_back(m[1]);
    } else if (section == "Options:" && std::regex_match(line, m, option_re)) {
      last = &h.options[m[2]];
      last->names = m[1];
      last->text = m[3];
    } else if (last != nullptr && line.size() > 30 && line.compare(0, 30, std::string(30, ' ')) == 0) {
      last->text += " " + line.substr(30);  // description continued on the next line
    }
  }
  return h;
}

void walk(const std::vector<std::string>& path, std::map<std::string, Help>& out) {
  Help h = help_of(path);
  std::string name = "poise";
  for (const auto& p : path) {
    name += " " + p;
  }
  for (const auto& sub : h.subcommands) {
    std::vector<std::string> next = path;
    next.push_back(sub);
    walk(next, out);
  }
  out[name] = std::move(h);
}

bool contains(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

TEST(CliGrammar, EverySubcommandsSharedOptionsHaveOneNameAndMeaning) {
  std::map<std::string, Help> helps;
  walk({}, helps);
  ASSERT_GE(helps.size(), 30U) << "the walk found too few subcommands";
  // The meaning of each shared option, as docs/TOOLS.md states it: a phrase its help must hold.
  const std::map<std::string, std::string> meaning{
      {"--output", "Output file:"},
      {"--out-dir", "Output directory:"},
      {"--dds-profile", "DDS participant profile"},
      {"--domain", "DDS domain id"},
      {"--json", "JSON"},
      {"--rate", "Hz"},
      {"--speed", "Speed factor"},
      {"--duration", "FLOAT"},
      {"--imu-topic", "topic"},
      {"--topic", "key=name"},
      {"--set", "KEY=VALUE"},
  };
  // Spellings retired by the grammar (still accepted, hidden, with a deprecation note).
  const std::vector<std::string> retired{"--out", "--profile", "--write", "--topics", "--seconds"};
  std::map<std::string, int> uses;
  for (const auto& [command, h] : helps) {
    SCOPED_TRACE(command);
    EXPECT_EQ(h.exit_code, 0) << "--help failed with POISE_DOMAIN=abc";
    for (const auto& [name, opt] : h.options) {
      ++uses[name];
      for (const auto& r : retired) {
        EXPECT_NE(name, r) << "retired spelling shown in --help";
      }
      const auto it = meaning.find(name);
      if (it != meaning.end()) {
        EXPECT_TRUE(contains(opt.text, it->second)) << name << " means '" << opt.text << "', expected '"
                                                    << it->second << "'";
      }
      if (name == "--output") {
        EXPECT_EQ(opt.names, "-o,--output");
      }
    }
  }
  // The table's options are really shared (else the check above checks nothing).
  for (const char* shared : {"--output", "--out-dir", "--dds-profile", "--domain", "--json", "--duration", "--set"}) {
    EXPECT_GE(uses[shared], 2) << shared;
  }
}

// Every command that makes a DDS participant takes both --domain and --dds-profile (issue 37: the
// docs list --dds-profile for every DDS command; echo, topics and demo refused it).
TEST(CliGrammar, EveryCommandWithADomainAlsoTakesADdsProfile) {
  std::map<std::string, Help> helps;
  walk({}, helps);
  int dds_commands = 0;
  for (const auto& [command, h] : helps) {
    if (h.options.count("--domain") == 0) {
      continue;
    }
    ++dds_commands;
    EXPECT_EQ(h.options.count("--dds-profile"), 1U) << command << " has --domain but no --dds-profile";
  }
  constexpr int kAtLeastDdsCommands = 10;  // run, demo, imu, camera, echo, topics, record, replay, ...
  EXPECT_GE(dds_commands, kAtLeastDdsCommands);
}

TEST(CliGrammar, RequiredOutputsSayRequiredInHelp) {
  // CLI11 prints REQUIRED after an option it requires; an option with an old spelling is checked
  // after parsing and says "(required)" in its text (docs/TOOLS.md).
  const std::vector<std::pair<std::vector<std::string>, std::string>> required{
      {{"record"}, "--output"}, {{"process"}, "--output"}, {{"eval", "broad"}, "--out-dir"},
      {{"tune"}, "--out-dir"},  {{"tune"}, "--output"}};
  for (const auto& [path, option] : required) {
    const Help h = help_of(path);
    SCOPED_TRACE(path.back() + " " + option);
    const auto it = h.options.find(option);
    ASSERT_NE(it, h.options.end());
    EXPECT_TRUE(contains(it->second.text, "REQUIRED") || contains(it->second.text, "(required)"))
        << it->second.text;
  }
  // and CLI11 refuses the command without it, naming the option, exit 2
  const RunResult r = run({bin("poise"), "process", bin("poise")}, 30s);
  EXPECT_EQ(r.exit_code, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "--output")) << r.output;
}

TEST(CliGrammar, TheBenchmarksTakeDurationAndStillAcceptSecondsWithANote) {
  for (const std::vector<std::string>& path :
       {std::vector<std::string>{"bench", "record"}, {"bench", "replay"}, {"bench", "latency"}, {"bench", "imu"}}) {
    const Help h = help_of(path);
    SCOPED_TRACE(path.back());
    EXPECT_EQ(h.options.count("--duration"), 1U);
    EXPECT_EQ(h.options.count("--seconds"), 0U) << "the old spelling is hidden";
  }
  // the old spelling: parsed, same validation, a note on stderr (--help stops before running)
  const RunResult old = run({bin("poise"), "bench", "imu", "--seconds", "0.1", "--lines", "10"}, 30s);
  EXPECT_EQ(old.exit_code, 2) << "0.1 s is below the range of --duration: " << old.output;
  const RunResult ok = run({bin("poise"), "bench", "imu", "--seconds", "1", "--lines", "10"}, 60s);
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_TRUE(contains(ok.output, "'poise bench imu --seconds' is deprecated, use --duration")) << ok.output;
}

TEST(CliGrammar, ABadPoiseDomainIsAnErrorNamingTheVariable) {
  const RunResult r = run({bin("poise"), "topics", "--duration", "0.1"}, 30s, {"POISE_DOMAIN=abc"});
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "POISE_DOMAIN='abc'")) << r.output;
  EXPECT_FALSE(contains(r.output, "internal error")) << r.output;
  // --domain given: the environment is not consulted
  const RunResult given = run({bin("poise"), "topics", "--duration", "0.1", "--domain", "231"}, 30s,
                              {"POISE_DOMAIN=abc"});
  EXPECT_EQ(given.exit_code, 0) << given.output;
}

TEST(CliGrammar, AnOldSpellingStillWorksWithADeprecationNote) {
  const std::string dir = ::testing::TempDir() + "/grammar_tags";
  const RunResult r = run({bin("poise"), "tags", "render", "--out", dir + ".png", "--ids", "3"}, 60s);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "'poise tags render --out' is deprecated, use -o/--output")) << r.output;
  const RunResult missing = run({bin("poise"), "tags", "render", "--ids", "3"}, 60s);
  EXPECT_EQ(missing.exit_code, 2) << missing.output;
  EXPECT_TRUE(contains(missing.output, "--output")) << missing.output;
}

}  // namespace
}  // namespace poise::testing
