// No function over 100 lines without a reason written beside it (issue 30): a function body in
// components/, drivers/ or tools/poise/ longer than kMaxFunctionLines carries, in the comment just
// above its signature, "not split:" and why. The scan reads clang-formatted code: a function starts
// at a line at namespace or class indentation (0 or 2 spaces) that opens a parameter list, and ends
// at the closing brace at the same indentation.
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace poise::testing {
namespace {

namespace fs = std::filesystem;

constexpr int kMaxFunctionLines = 100;  // signature to closing brace, both included
constexpr int kReasonSearchLines = 4;   // comment lines above the signature searched for the reason

struct LongFunction {
  std::string file;
  int line = 0;
  int length = 0;
  std::string name;
  bool has_reason = false;
};

int indent_of(const std::string& line) {
  int n = 0;
  while (n < static_cast<int>(line.size()) && line[static_cast<size_t>(n)] == ' ') {
    ++n;
  }
  return n;
}

/// The functions longer than `max_lines` in one file's text.
std::vector<LongFunction> long_functions(const std::string& text, const std::string& file, int max_lines) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) {
    lines.push_back(l);
  }
  static const std::regex header(R"(^( {0,2})[A-Za-z_][\w:<>,\s\*&\[\]]*?\b([\w:~]+)\s*\()");
  static const std::regex not_function(R"(^\s*(namespace|struct|class|enum|using|typedef|return|if|for|while|switch|else|case|#))");
  std::vector<LongFunction> out;
  for (size_t i = 0; i < lines.size(); ++i) {
    std::smatch m;
    const std::string& l = lines[i];
    if (!std::regex_search(l, m, header) || std::regex_search(l, not_function) || l.find(';') != std::string::npos ||
        (indent_of(l) != 0 && indent_of(l) != 2)) {
      continue;
    }
    size_t open = i;  // the line of the body's opening brace (the signature may span lines)
    while (open < lines.size() && lines[open].find('{') == std::string::npos &&
           lines[open].find(';') == std::string::npos) {
      ++open;
    }
    if (open >= lines.size() || lines[open].find('{') == std::string::npos) {
      continue;
    }
    const int indent = indent_of(l);
    const std::string closing = std::string(static_cast<size_t>(indent), ' ') + "}";
    size_t close = open;
    if (lines[open].find('}') == std::string::npos) {  // not a one-line body
      close = open + 1;
      while (close < lines.size() && !(lines[close].rfind(closing, 0) == 0 && indent_of(lines[close]) == indent)) {
        ++close;
      }
    }
    const int length = static_cast<int>(close - i) + 1;
    if (length > max_lines) {
      bool reason = false;
      for (size_t k = i >= static_cast<size_t>(kReasonSearchLines) ? i - kReasonSearchLines : 0; k < i; ++k) {
        reason = reason || lines[k].find("not split:") != std::string::npos;
      }
      out.push_back({file, static_cast<int>(i) + 1, length, m[2], reason});
    }
    i = close;
  }
  return out;
}

std::string read(const fs::path& p) {
  std::ifstream in(p);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(Functions, NoFunctionInComponentsDriversOrToolsIsOver100LinesWithoutAReasonAboveIt) {
  const fs::path root = source_path(".");
  std::ostringstream missing;
  int files = 0;
  int long_with_reason = 0;
  for (const char* top : {"components", "drivers", "tools/poise"}) {
    for (const auto& e : fs::recursive_directory_iterator(root / top)) {
      const std::string ext = e.path().extension().string();
      if (!e.is_regular_file() || (ext != ".cpp" && ext != ".h")) {
        continue;
      }
      ++files;
      const std::string rel = fs::relative(e.path(), root).string();
      for (const LongFunction& f : long_functions(read(e.path()), rel, kMaxFunctionLines)) {
        if (f.has_reason) {
          ++long_with_reason;
        } else {
          missing << "  " << f.file << ":" << f.line << " " << f.name << " (" << f.length << " lines)\n";
        }
      }
    }
  }
  EXPECT_GT(files, 200) << "the scan found too few source files: is POISE_SOURCE_DIR right?";
  EXPECT_TRUE(missing.str().empty()) << "functions over " << kMaxFunctionLines
                                     << " lines with no \"not split: <reason>\" comment above them:\n"
                                     << missing.str();
  std::cout << long_with_reason << " function(s) over " << kMaxFunctionLines << " lines carry a reason\n";
}

// The scanner on text built here (the oracle is the construction): a 101-line function without a
// reason is reported with its line and length, one with a reason and a 100-line one are not.
TEST(Functions, GivenFunctionsAroundTheLimitThenOnlyTheLongOneWithoutAReasonIsReported) {
  auto body = [](const std::string& signature, int total_lines) {
    std::string s = signature + " {\n";
    for (int k = 0; k < total_lines - 2; ++k) {
      s += "  ++x;\n";
    }
    return s + "}\n";
  };
  const std::string text = "namespace a {\n\n" + body("int too_long(int x)", 101) + "\n" +
                           body("int at_limit(int x)", 100) + "\n// not split: one table, read top to bottom.\n" +
                           body("int explained(int x)", 150) + "\n}  // namespace a\n";
  const std::vector<LongFunction> found = long_functions(text, "t.cpp", 100);
  ASSERT_EQ(found.size(), 2u);
  EXPECT_EQ(found[0].name, "too_long");
  EXPECT_EQ(found[0].line, 3);
  EXPECT_EQ(found[0].length, 101);
  EXPECT_FALSE(found[0].has_reason);
  EXPECT_EQ(found[1].name, "explained");
  EXPECT_TRUE(found[1].has_reason);
}

}  // namespace
}  // namespace poise::testing
