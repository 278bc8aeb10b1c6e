// The docs stand alone (issue 20): every relative link in README.md and docs/*.md resolves to a
// file inside the repository, and every `poise <command>` shown in a fenced code block exists
// (`poise <command> --help` exits 0).
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

namespace poise::testing {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

std::vector<fs::path> doc_files() {
  std::vector<fs::path> out{fs::path(source_path("README.md"))};
  for (const auto& e : fs::directory_iterator(source_path("docs"))) {
    if (e.path().extension() == ".md") {
      out.push_back(e.path());
    }
  }
  return out;
}

TEST(Docs, EveryRelativeLinkResolvesInsideTheRepository) {
  const fs::path root = fs::canonical(source_path("."));
  const std::regex link(R"(\]\(([^)\s]+)\))");
  int checked = 0;
  for (const fs::path& doc : doc_files()) {
    const std::string text = read_file(doc);
    for (auto it = std::sregex_iterator(text.begin(), text.end(), link); it != std::sregex_iterator(); ++it) {
      std::string target = (*it)[1];
      if (target.rfind("http://", 0) == 0 || target.rfind("https://", 0) == 0 || target.rfind("mailto:", 0) == 0 ||
          target[0] == '#') {
        continue;
      }
      target = target.substr(0, target.find('#'));
      const fs::path resolved = fs::weakly_canonical(doc.parent_path() / target);
      const std::string rel = fs::relative(resolved, root).string();
      EXPECT_FALSE(rel.empty() || rel.rfind("..", 0) == 0) << doc.filename() << ": '" << target << "' leaves the repository";
      EXPECT_TRUE(fs::exists(resolved)) << doc.filename() << ": '" << target << "' does not exist";
      ++checked;
    }
  }
  EXPECT_GT(checked, 20);
}

TEST(Docs, EveryPoiseCommandInACodeBlockExists) {
  // `poise` as a word (start of line, after a space, `$ ` or a path), then the command words (a
  // word ends at a space: `run.mcap` or `a/b` are arguments, not commands)
  const std::regex cmd(R"((?:^|[\s/$`(])poise((?:\s+[a-z][a-z0-9-]*(?=\s|$)){1,2}))");
  std::set<std::string> commands;
  for (const fs::path& doc : doc_files()) {
    std::istringstream in(read_file(doc));
    std::string line;
    bool in_block = false;
    while (std::getline(in, line)) {
      if (line.rfind("```", 0) == 0) {
        in_block = !in_block;
        continue;
      }
      std::smatch m;
      if (in_block && std::regex_search(line, m, cmd)) {
        commands.insert(m[1]);
      }
    }
  }
  ASSERT_GT(commands.size(), 10U);
  for (const std::string& words : commands) {
    std::vector<std::string> argv{bin("poise")};
    std::istringstream ws(words);
    for (std::string w; ws >> w;) {
      argv.push_back(w);
    }
    argv.emplace_back("--help");
    const RunResult r = run(argv, 30s);
    EXPECT_EQ(r.exit_code, 0) << "poise" << words << " --help:\n" << r.output.substr(0, 400);
  }
}

}  // namespace
}  // namespace poise::testing
