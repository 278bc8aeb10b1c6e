// The tree tells the layers (docs/DEVELOPING.md "Layers"): every `#include "poise/<area>/..."` in
// components/, drivers/ and tools/poise/ points at the same layer or one below. The layer table is
// read from docs/DEVELOPING.md itself, so the drawing and this check cannot drift apart; a folder
// that provides headers (include/poise/<area>/) and is missing from the table fails too.
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace poise::testing {
namespace {

namespace fs = std::filesystem;

struct Layer {
  int number = 0;
  std::string folder;  // relative to the root, "components/estimators/*" matches one level below
};

struct Violation {
  std::string file;
  int line = 0;
  std::string include;
  int from_layer = 0;
  int to_layer = 0;
};

struct LayerCheck {
  std::vector<Violation> violations;
  std::vector<std::string> unlayered;  // folders with code or headers that no table row covers
  int includes_checked = 0;
};

/// The rows `| N | `folder`, `folder` | what |` of the markdown table under "## Layers".
std::vector<Layer> read_layer_table(const std::string& markdown) {
  std::vector<Layer> out;
  const auto start = markdown.find("\n## Layers");
  if (start == std::string::npos) {
    return out;
  }
  const auto end = markdown.find("\n## ", start + 1);
  std::istringstream section(markdown.substr(start, end == std::string::npos ? std::string::npos : end - start));
  const std::regex row(R"(^\|\s*(\d+)\s*\|([^|]*)\|)");
  const std::regex folder("`([^`]+)`");
  std::string line;
  while (std::getline(section, line)) {
    std::smatch m;
    if (!std::regex_search(line, m, row)) {
      continue;
    }
    const int number = std::stoi(m[1]);
    const std::string cell = m[2];
    for (auto it = std::sregex_iterator(cell.begin(), cell.end(), folder); it != std::sregex_iterator(); ++it) {
      std::string f = (*it)[1];
      while (!f.empty() && f.back() == '/') {
        f.pop_back();
      }
      out.push_back({number, f});
    }
  }
  return out;
}

/// The folders that hold code: components/X, drivers/X, tools/poise/X, and one level further
/// below a folder that only groups others (components/estimators/Y).
std::vector<std::string> code_folders(const fs::path& root) {
  std::vector<std::string> out;
  for (const char* top : {"components", "drivers", "tools/poise"}) {
    if (!fs::is_directory(root / top)) {
      continue;
    }
    for (const auto& e : fs::directory_iterator(root / top)) {
      if (!e.is_directory()) {
        continue;
      }
      if (fs::exists(e.path() / "CMakeLists.txt")) {
        out.push_back(fs::relative(e.path(), root).string());
        continue;
      }
      for (const auto& g : fs::directory_iterator(e.path())) {
        if (g.is_directory() && fs::exists(g.path() / "CMakeLists.txt")) {
          out.push_back(fs::relative(g.path(), root).string());
        }
      }
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::optional<int> layer_of_folder(const std::vector<Layer>& table, const std::string& folder) {
  for (const Layer& l : table) {
    if (l.folder == folder) {
      return l.number;
    }
    if (l.folder.size() > 2 && l.folder.compare(l.folder.size() - 2, 2, "/*") == 0) {
      const std::string parent = l.folder.substr(0, l.folder.size() - 1);  // "components/estimators/"
      if (folder.rfind(parent, 0) == 0 && folder.find('/', parent.size()) == std::string::npos) {
        return l.number;
      }
    }
  }
  return std::nullopt;
}

/// Checks the tree at ROOT against the layer table: every poise include points at the same layer
/// or below. An include area is the folder whose include/poise/<area>/ provides it; the
/// generated type support (`poise/msg`, `poise/ros2`, from idl/) belongs to the `idl` row.
LayerCheck check_layers(const fs::path& root, const std::vector<Layer>& table) {
  LayerCheck result;
  std::map<std::string, int> area_layer;       // "core" -> 0
  std::map<std::string, std::string> area_dir;  // "core" -> "components/core"
  std::map<std::string, int> folder_layer;
  for (const std::string& folder : code_folders(root)) {
    const std::optional<int> layer = layer_of_folder(table, folder);
    if (!layer) {
      result.unlayered.push_back(folder);
      continue;
    }
    folder_layer[folder] = *layer;
    const fs::path inc = root / folder / "include" / "poise";
    if (fs::is_directory(inc)) {
      for (const auto& e : fs::directory_iterator(inc)) {
        if (e.is_directory()) {
          area_layer[e.path().filename().string()] = *layer;
          area_dir[e.path().filename().string()] = folder;
        }
      }
    }
  }
  if (const std::optional<int> idl = layer_of_folder(table, "idl")) {
    area_layer["msg"] = *idl;
    area_layer["ros2"] = *idl;
  }
  const std::regex include_re(R"re(^\s*#\s*include\s*["<]poise/([a-z0-9_]+)/[^">]+[">])re");
  for (const auto& [folder, layer] : folder_layer) {
    for (const auto& e : fs::recursive_directory_iterator(root / folder)) {
      const std::string ext = e.path().extension().string();
      if (!e.is_regular_file() || (ext != ".cpp" && ext != ".h" && ext != ".hpp")) {
        continue;
      }
      std::istringstream text(read_file(e.path()));
      std::string line;
      int number = 0;
      while (std::getline(text, line)) {
        ++number;
        std::smatch m;
        if (!std::regex_search(line, m, include_re)) {
          continue;
        }
        ++result.includes_checked;
        const auto to = area_layer.find(m[1]);
        const int to_layer = to == area_layer.end() ? 1000 : to->second;  // unknown area: refused
        if (to_layer > layer) {
          result.violations.push_back(
              {fs::relative(e.path(), root).string(), number, line, layer, to_layer});
        }
      }
    }
  }
  return result;
}

std::string describe(const LayerCheck& c) {
  std::ostringstream s;
  for (const Violation& v : c.violations) {
    s << "  " << v.file << ":" << v.line << " (layer " << v.from_layer << ") includes a layer "
      << (v.to_layer == 1000 ? std::string("no folder provides") : std::to_string(v.to_layer))
      << " header: " << v.include << "\n";
  }
  for (const std::string& f : c.unlayered) {
    s << "  " << f << " is in no row of docs/DEVELOPING.md \"Layers\"\n";
  }
  return s.str();
}

TEST(Layers, TheTableInDevelopingMdNamesEveryCodeFolderOfTheTree) {
  const fs::path root = source_path(".");
  const std::vector<Layer> table = read_layer_table(read_file(root / "docs" / "DEVELOPING.md"));
  ASSERT_GE(table.size(), 8u) << "docs/DEVELOPING.md has no \"## Layers\" table";
  const LayerCheck c = check_layers(root, table);
  EXPECT_TRUE(c.unlayered.empty()) << describe(c);
  // Every row names a folder that exists (a renamed folder fails here, not silently).
  for (const Layer& l : table) {
    const std::string f = l.folder.size() > 2 && l.folder.substr(l.folder.size() - 2) == "/*"
                              ? l.folder.substr(0, l.folder.size() - 2)
                              : l.folder;
    EXPECT_TRUE(fs::is_directory(root / f)) << "the layer table names " << l.folder << ", which does not exist";
  }
}

TEST(Layers, EveryIncludeInComponentsDriversAndToolsPointsToItsOwnLayerOrBelow) {
  const fs::path root = source_path(".");
  const std::vector<Layer> table = read_layer_table(read_file(root / "docs" / "DEVELOPING.md"));
  ASSERT_GE(table.size(), 8u) << "docs/DEVELOPING.md has no \"## Layers\" table";
  const LayerCheck c = check_layers(root, table);
  EXPECT_TRUE(c.violations.empty()) << c.violations.size() << " include(s) point up the layers:\n" << describe(c);
  // The tree holds several hundred poise includes; far fewer means the scan missed the tree.
  constexpr int kAtLeastIncludes = 300;
  EXPECT_GE(c.includes_checked, kAtLeastIncludes);
}

// The checker itself, on a tree built here with one include that points up (the oracle is the
// tree's construction: exactly that line, and nothing else, must be reported).
TEST(Layers, GivenATreeWithAnUpwardIncludeThenExactlyThatLineIsReported) {
  const fs::path root = fs::temp_directory_path() / ("poise_layers_" + std::to_string(::getpid()));
  fs::remove_all(root);
  auto write = [&](const std::string& rel, const std::string& text) {
    fs::create_directories((root / rel).parent_path());
    std::ofstream(root / rel) << text;
  };
  write("components/core/CMakeLists.txt", "");
  write("components/core/include/poise/core/types.h", "#pragma once\n");
  write("components/estimators/kf/CMakeLists.txt", "");
  write("components/estimators/kf/include/poise/kf/kf.h", "#include \"poise/core/types.h\"\n");
  write("components/estimators/kf/src/kf.cpp", "#include \"poise/kf/kf.h\"\n\n#include <poise/cli/common.h>\n");
  write("tools/poise/cli/CMakeLists.txt", "");
  write("tools/poise/cli/include/poise/cli/common.h", "#include \"poise/kf/kf.h\"\n");
  write("drivers/unlisted/CMakeLists.txt", "");
  const std::vector<Layer> table = read_layer_table(
      "x\n## Layers\n| layer | folders |\n|---|---|\n| 0 | `components/core` |\n"
      "| 1 | `components/estimators/*` |\n| 8 | `tools/poise/*` |\n## Next\n| 9 | `drivers/unlisted` |\n");
  ASSERT_EQ(table.size(), 3u);
  const LayerCheck c = check_layers(root, table);
  ASSERT_EQ(c.violations.size(), 1u) << describe(c);
  EXPECT_EQ(c.violations[0].file, "components/estimators/kf/src/kf.cpp");
  EXPECT_EQ(c.violations[0].line, 3);
  EXPECT_EQ(c.violations[0].from_layer, 1);
  EXPECT_EQ(c.violations[0].to_layer, 8);
  EXPECT_EQ(c.includes_checked, 4);
  ASSERT_EQ(c.unlayered.size(), 1u);
  EXPECT_EQ(c.unlayered[0], "drivers/unlisted");
  fs::remove_all(root);
}

}  // namespace
}  // namespace poise::testing
