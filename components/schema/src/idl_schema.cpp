#include "poise/schema/idl_schema.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <dirent.h>
#include <fstream>
#include <functional>
#include <set>
#include <sstream>

namespace poise::schema {

std::size_t primitive_size(PrimitiveKind kind) {
  switch (kind) {
    case PrimitiveKind::kBool:
    case PrimitiveKind::kOctet:
    case PrimitiveKind::kChar:
    case PrimitiveKind::kInt8:
    case PrimitiveKind::kUInt8:
      return 1;
    case PrimitiveKind::kInt16:
    case PrimitiveKind::kUInt16:
      return 2;
    case PrimitiveKind::kInt32:
    case PrimitiveKind::kUInt32:
    case PrimitiveKind::kFloat:
      return 4;
    case PrimitiveKind::kInt64:
    case PrimitiveKind::kUInt64:
    case PrimitiveKind::kDouble:
      return 8;
  }
  return 1;
}

const char* primitive_name(PrimitiveKind kind) {
  switch (kind) {
    case PrimitiveKind::kBool: return "boolean";
    case PrimitiveKind::kOctet: return "octet";
    case PrimitiveKind::kChar: return "char";
    case PrimitiveKind::kInt8: return "int8";
    case PrimitiveKind::kUInt8: return "uint8";
    case PrimitiveKind::kInt16: return "int16";
    case PrimitiveKind::kUInt16: return "uint16";
    case PrimitiveKind::kInt32: return "int32";
    case PrimitiveKind::kUInt32: return "uint32";
    case PrimitiveKind::kInt64: return "int64";
    case PrimitiveKind::kUInt64: return "uint64";
    case PrimitiveKind::kFloat: return "float";
    case PrimitiveKind::kDouble: return "double";
  }
  return "?";
}

bool StructDef::has_key() const {
  return std::any_of(members.begin(), members.end(), [](const Member& m) { return m.key; });
}

namespace {

// ---------------------------------------------------------------------------------------------
// Tokenizer

struct Token {
  enum class Kind { kIdent, kNumber, kString, kPunct, kEnd };
  Kind kind = Kind::kEnd;
  std::string text;
  int line = 0;
};

class Lexer {
 public:
  Lexer(std::string file, const std::string& text) : file_(std::move(file)) { tokenize(text); }
  [[nodiscard]] const std::vector<Token>& tokens() const { return tokens_; }
  [[nodiscard]] const std::vector<std::string>& includes() const { return includes_; }

 private:
  [[noreturn]] void fail(int line, const std::string& what) const {
    throw SchemaError(file_ + ":" + std::to_string(line) + ": " + what);
  }

  void tokenize(const std::string& s) {
    int line = 1;
    std::size_t i = 0;
    bool line_start = true;
    const std::size_t n = s.size();
    while (i < n) {
      const char c = s[i];
      if (c == '\n') {
        ++line;
        ++i;
        line_start = true;
        continue;
      }
      if (std::isspace(static_cast<unsigned char>(c)) != 0) {
        ++i;
        continue;
      }
      if (c == '#' && line_start) {
        const std::size_t end = s.find('\n', i);
        const std::string directive = s.substr(i, end == std::string::npos ? n - i : end - i);
        preprocessor(directive, line);
        i = end == std::string::npos ? n : end;
        continue;
      }
      line_start = false;
      if (c == '/' && i + 1 < n && s[i + 1] == '/') {
        while (i < n && s[i] != '\n') {
          ++i;
        }
        continue;
      }
      if (c == '/' && i + 1 < n && s[i + 1] == '*') {
        const std::size_t end = s.find("*/", i + 2);
        if (end == std::string::npos) {
          fail(line, "unterminated /* comment");
        }
        line += static_cast<int>(std::count(s.begin() + static_cast<std::ptrdiff_t>(i),
                                            s.begin() + static_cast<std::ptrdiff_t>(end), '\n'));
        i = end + 2;
        continue;
      }
      Token t;
      t.line = line;
      if (std::isalpha(static_cast<unsigned char>(c)) != 0 || c == '_') {
        std::size_t j = i;
        while (j < n && (std::isalnum(static_cast<unsigned char>(s[j])) != 0 || s[j] == '_')) {
          ++j;
        }
        t.kind = Token::Kind::kIdent;
        t.text = s.substr(i, j - i);
        i = j;
      } else if (std::isdigit(static_cast<unsigned char>(c)) != 0) {
        std::size_t j = i;
        while (j < n && (std::isalnum(static_cast<unsigned char>(s[j])) != 0 || s[j] == '.')) {
          ++j;
        }
        t.kind = Token::Kind::kNumber;
        t.text = s.substr(i, j - i);
        i = j;
      } else if (c == '"' || c == '\'') {
        std::size_t j = i + 1;
        while (j < n && s[j] != c && s[j] != '\n') {
          j += s[j] == '\\' ? 2 : 1;
        }
        if (j >= n || s[j] != c) {
          fail(line, "unterminated literal");
        }
        t.kind = Token::Kind::kString;
        t.text = s.substr(i, j + 1 - i);
        i = j + 1;
      } else if (c == ':' && i + 1 < n && s[i + 1] == ':') {
        t.kind = Token::Kind::kPunct;
        t.text = "::";
        i += 2;
      } else if (std::string_view("{};:<>[],=()@-+*/").find(c) != std::string_view::npos) {
        t.kind = Token::Kind::kPunct;
        t.text = std::string(1, c);
        ++i;
      } else {
        fail(line, std::string("unexpected character '") + c + "'");
      }
      tokens_.push_back(std::move(t));
    }
    Token end;
    end.line = line;
    tokens_.push_back(end);
  }

  void preprocessor(const std::string& directive, int line) {
    std::istringstream in(directive.substr(1));
    std::string word;
    in >> word;
    if (word != "include") {
      return;  // #pragma, include guards: no effect on the types
    }
    std::string rest;
    std::getline(in, rest);
    const std::size_t open = rest.find_first_of("\"<");
    const std::size_t close = rest.find_last_of("\">");
    if (open == std::string::npos || close == std::string::npos || close <= open + 1) {
      fail(line, "malformed #include");
    }
    std::string path = rest.substr(open + 1, close - open - 1);
    const std::size_t slash = path.find_last_of('/');
    includes_.push_back(slash == std::string::npos ? path : path.substr(slash + 1));
  }

  std::string file_;
  std::vector<Token> tokens_;
  std::vector<std::string> includes_;
};

// ---------------------------------------------------------------------------------------------
// Parser

class Parser {
 public:
  Parser(std::string file, const std::vector<Token>& tokens, TypeTable& table)
      : file_(std::move(file)), tokens_(tokens), table_(table) {}

  void parse() {
    while (peek().kind != Token::Kind::kEnd) {
      definition();
    }
    if (!scope_.empty()) {
      fail("missing '}' for module " + scope_.back());
    }
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw SchemaError(file_ + ":" + std::to_string(peek().line) + ": " + what);
  }
  [[nodiscard]] const Token& peek(std::size_t ahead = 0) const {
    return tokens_[std::min(pos_ + ahead, tokens_.size() - 1)];
  }
  Token next() {
    Token t = peek();
    if (pos_ + 1 < tokens_.size()) {
      ++pos_;
    }
    return t;
  }
  [[nodiscard]] bool is(const char* text) const {
    return peek().kind != Token::Kind::kString && peek().text == text;
  }
  bool accept(const char* text) {
    if (is(text)) {
      next();
      return true;
    }
    return false;
  }
  void expect(const char* text) {
    if (!accept(text)) {
      fail(std::string("expected '") + text + "' but found '" + peek().text + "'");
    }
  }
  std::string identifier(const char* what) {
    if (peek().kind != Token::Kind::kIdent) {
      fail(std::string("expected ") + what + " but found '" + peek().text + "'");
    }
    return next().text;
  }

  [[nodiscard]] std::string scoped(const std::string& simple) const {
    std::string out;
    for (const auto& m : scope_) {
      out += m + "::";
    }
    return out + simple;
  }

  // Annotations before a definition or member; returns true if @key (not @key(FALSE)) was seen.
  bool annotations() {
    bool key = false;
    while (accept("@")) {
      const std::string name = identifier("an annotation name");
      std::string args;
      if (accept("(")) {
        int depth = 1;
        while (depth > 0) {
          if (peek().kind == Token::Kind::kEnd) {
            fail("unterminated annotation @" + name);
          }
          const Token t = next();
          if (t.text == "(") {
            ++depth;
          } else if (t.text == ")") {
            --depth;
            if (depth == 0) {
              break;
            }
          }
          args += t.text;
        }
      }
      if (name == "key" || name == "Key") {
        std::string lower = args;
        std::transform(lower.begin(), lower.end(), lower.begin(),
                       [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
        key = lower != "false";
      }
    }
    return key;
  }

  void definition() {
    annotations();
    if (accept(";")) {
      return;
    }
    const Token& t = peek();
    if (t.kind != Token::Kind::kIdent) {
      fail("expected a definition but found '" + t.text + "'");
    }
    if (t.text == "module") {
      module();
    } else if (t.text == "struct") {
      structure();
    } else if (t.text == "enum") {
      enumeration();
    } else if (t.text == "const") {
      constant();
    } else {
      fail("unsupported IDL construct '" + t.text +
           "' (supported: module, struct, enum, const; see idl_schema.h)");
    }
  }

  void module() {
    expect("module");
    scope_.push_back(identifier("a module name"));
    expect("{");
    while (!is("}")) {
      if (peek().kind == Token::Kind::kEnd) {
        fail("missing '}' for module " + scope_.back());
      }
      definition();
    }
    expect("}");
    expect(";");
    scope_.pop_back();
  }

  void structure() {
    expect("struct");
    StructDef def;
    def.name = scoped(identifier("a struct name"));
    def.file = file_;
    if (is(";")) {
      fail("forward declarations are not supported (struct " + def.name + ")");
    }
    if (is(":")) {
      fail("struct inheritance is not supported (struct " + def.name + ")");
    }
    if (table_.has_type(def.name)) {
      fail("type " + def.name + " is defined twice");
    }
    expect("{");
    std::set<std::string> names;
    while (!accept("}")) {
      if (peek().kind == Token::Kind::kEnd) {
        fail("missing '}' for struct " + def.name);
      }
      const bool key = annotations();
      const TypeSpec base = type_spec();
      do {
        Member m;
        m.name = identifier("a member name");
        m.key = key;
        std::vector<std::uint32_t> dims;
        while (accept("[")) {
          const std::int64_t d = integer_expression();
          if (d <= 0 || d > 100000000) {
            fail("array dimension of " + m.name + " must be in 1..1e8");
          }
          dims.push_back(static_cast<std::uint32_t>(d));
          expect("]");
        }
        TypeSpec t = base;
        for (auto it = dims.rbegin(); it != dims.rend(); ++it) {
          TypeSpec arr;
          arr.kind = TypeSpec::Kind::kArray;
          arr.bound = *it;
          arr.element = std::make_shared<const TypeSpec>(t);
          t = arr;
        }
        m.type = t;
        if (!names.insert(m.name).second) {
          fail("member " + m.name + " is declared twice in " + def.name);
        }
        def.members.push_back(std::move(m));
      } while (accept(","));
      expect(";");
    }
    expect(";");
    if (def.members.empty()) {
      fail("struct " + def.name + " has no members");
    }
    table_.add_struct(std::move(def));
  }

  void enumeration() {
    expect("enum");
    EnumDef def;
    def.name = scoped(identifier("an enum name"));
    if (table_.has_type(def.name)) {
      fail("type " + def.name + " is defined twice");
    }
    expect("{");
    do {
      if (is("@") && peek(1).text == "value") {
        fail("@value on enumerators is not supported (enum " + def.name + ")");
      }
      annotations();
      if (is("}")) {
        break;
      }
      def.enumerators.push_back(identifier("an enumerator"));
    } while (accept(","));
    expect("}");
    expect(";");
    if (def.enumerators.empty()) {
      fail("enum " + def.name + " has no enumerators");
    }
    table_.add_enum(std::move(def));
  }

  void constant() {
    expect("const");
    const std::size_t type_start = pos_;
    const TypeSpec t = type_spec();
    std::string type_text;
    for (std::size_t i = type_start; i < pos_; ++i) {
      type_text += tokens_[i].text;
      if (tokens_[i].kind == Token::Kind::kIdent && i + 1 < pos_ &&
          tokens_[i + 1].kind == Token::Kind::kIdent) {
        type_text += " ";
      }
    }
    ConstDef def;
    def.name = scoped(identifier("a constant name"));
    def.type = type_text;
    expect("=");
    std::optional<std::int64_t> value;
    const bool integral = t.kind == TypeSpec::Kind::kPrimitive &&
                          t.primitive != PrimitiveKind::kFloat &&
                          t.primitive != PrimitiveKind::kDouble &&
                          t.primitive != PrimitiveKind::kBool;
    if (integral) {
      const std::size_t start = pos_;
      value = integer_expression();
      for (std::size_t i = start; i < pos_; ++i) {
        def.value += tokens_[i].text;
      }
    } else {
      while (!is(";")) {
        if (peek().kind == Token::Kind::kEnd) {
          fail("missing ';' after const " + def.name);
        }
        def.value += next().text;
      }
    }
    expect(";");
    table_.add_constant(std::move(def), value);
  }

  // Integer literal, optionally negative, or the scoped name of an integer constant.
  std::int64_t integer_expression() {
    const bool negative = accept("-");
    std::int64_t v = 0;
    if (peek().kind == Token::Kind::kNumber) {
      const std::string text = next().text;
      char* end = nullptr;
      errno = 0;
      const unsigned long long parsed = std::strtoull(text.c_str(), &end, 0);
      if (*end != '\0' || errno != 0) {
        fail("'" + text + "' is not an integer");
      }
      v = static_cast<std::int64_t>(parsed);
    } else if (peek().kind == Token::Kind::kIdent || is("::")) {
      const std::string name = scoped_name_tokens();
      const auto found = resolve_constant(name);
      if (!found) {
        fail("unknown integer constant '" + name + "'");
      }
      v = *found;
    } else {
      fail("expected an integer but found '" + peek().text + "'");
    }
    return negative ? -v : v;
  }

  std::string scoped_name_tokens() {
    std::string name;
    if (accept("::")) {
      name = "::";
    }
    name += identifier("a name");
    while (accept("::")) {
      name += "::" + identifier("a name");
    }
    return name;
  }

  template <typename Lookup>
  std::optional<std::string> resolve(const std::string& name, Lookup exists) const {
    if (name.substr(0, 2) == "::") {
      const std::string absolute = name.substr(2);
      return exists(absolute) ? std::optional<std::string>(absolute) : std::nullopt;
    }
    for (std::size_t depth = scope_.size() + 1; depth-- > 0;) {
      std::string candidate;
      for (std::size_t i = 0; i < depth; ++i) {
        candidate += scope_[i] + "::";
      }
      candidate += name;
      if (exists(candidate)) {
        return candidate;
      }
    }
    return std::nullopt;
  }

  std::optional<std::int64_t> resolve_constant(const std::string& name) const {
    const auto full =
        resolve(name, [this](const std::string& c) { return table_.integer_constant(c).has_value(); });
    return full ? table_.integer_constant(*full) : std::nullopt;
  }

  std::uint32_t bound_expression(const char* what) {
    const std::int64_t b = integer_expression();
    if (b <= 0 || b > 100000000) {
      fail(std::string(what) + " bound must be in 1..1e8");
    }
    return static_cast<std::uint32_t>(b);
  }

  TypeSpec type_spec() {
    TypeSpec t;
    if (accept("sequence")) {
      expect("<");
      t.kind = TypeSpec::Kind::kSequence;
      t.element = std::make_shared<const TypeSpec>(type_spec());
      if (accept(",")) {
        t.bound = bound_expression("sequence");
      }
      expect(">");
      return t;
    }
    if (accept("string")) {
      t.kind = TypeSpec::Kind::kString;
      if (accept("<")) {
        t.bound = bound_expression("string");
        expect(">");
      }
      return t;
    }
    if (is("wstring") || is("wchar") || is("any") || is("fixed") || is("map")) {
      fail("unsupported type '" + peek().text + "'");
    }
    if (const auto p = primitive()) {
      t.kind = TypeSpec::Kind::kPrimitive;
      t.primitive = *p;
      return t;
    }
    const std::string name = scoped_name_tokens();
    const auto full = resolve(name, [this](const std::string& c) { return table_.has_type(c); });
    if (!full) {
      fail("unknown type '" + name + "' (types must be declared before use)");
    }
    t.kind = table_.find_struct(*full) != nullptr ? TypeSpec::Kind::kStruct : TypeSpec::Kind::kEnum;
    t.name = *full;
    return t;
  }

  std::optional<PrimitiveKind> primitive() {
    static const std::map<std::string, PrimitiveKind> kSimple = {
        {"boolean", PrimitiveKind::kBool},   {"octet", PrimitiveKind::kOctet},
        {"char", PrimitiveKind::kChar},      {"int8", PrimitiveKind::kInt8},
        {"uint8", PrimitiveKind::kUInt8},    {"int16", PrimitiveKind::kInt16},
        {"uint16", PrimitiveKind::kUInt16},  {"int32", PrimitiveKind::kInt32},
        {"uint32", PrimitiveKind::kUInt32},  {"int64", PrimitiveKind::kInt64},
        {"uint64", PrimitiveKind::kUInt64},  {"float", PrimitiveKind::kFloat},
        {"double", PrimitiveKind::kDouble},  {"short", PrimitiveKind::kInt16}};
    if (peek().kind != Token::Kind::kIdent) {
      return std::nullopt;
    }
    const auto it = kSimple.find(peek().text);
    if (it != kSimple.end()) {
      next();
      return it->second;
    }
    if (accept("unsigned")) {
      if (accept("short")) {
        return PrimitiveKind::kUInt16;
      }
      expect("long");
      return accept("long") ? PrimitiveKind::kUInt64 : PrimitiveKind::kUInt32;
    }
    if (accept("long")) {
      if (is("double")) {
        fail("long double is not supported");
      }
      return accept("long") ? PrimitiveKind::kInt64 : PrimitiveKind::kInt32;
    }
    return std::nullopt;
  }

  std::string file_;
  const std::vector<Token>& tokens_;
  TypeTable& table_;
  std::size_t pos_ = 0;
  std::vector<std::string> scope_;
};

void parse_file(const std::string& name, const std::map<std::string, std::string>& files,
                TypeTable& table, std::set<std::string>& done, std::vector<std::string>& stack) {
  if (done.count(name) != 0) {
    return;
  }
  if (std::find(stack.begin(), stack.end(), name) != stack.end()) {
    return;  // include cycle: the outer file is already being parsed
  }
  const auto it = files.find(name);
  if (it == files.end()) {
    throw SchemaError("IDL file '" + name + "' not found" +
                      (stack.empty() ? std::string() : " (included from " + stack.back() + ")"));
  }
  stack.push_back(name);
  const Lexer lexer(name, it->second);
  for (const auto& inc : lexer.includes()) {
    parse_file(inc, files, table, done, stack);
  }
  Parser(name, lexer.tokens(), table).parse();
  stack.pop_back();
  done.insert(name);
}

std::size_t align(std::size_t offset, std::size_t size) {
  return (size - offset % size) % size;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// TypeTable

void TypeTable::add_struct(StructDef def) {
  struct_index_[def.name] = structs_.size();
  order_.push_back({true, structs_.size()});
  structs_.push_back(std::move(def));
}

void TypeTable::add_enum(EnumDef def) {
  enum_index_[def.name] = enums_.size();
  order_.push_back({false, enums_.size()});
  enums_.push_back(std::move(def));
}

void TypeTable::add_constant(ConstDef def, std::optional<std::int64_t> integer_value) {
  if (integer_value) {
    integer_constants_[def.name] = *integer_value;
  }
  constants_.push_back(std::move(def));
}

std::optional<std::int64_t> TypeTable::integer_constant(std::string_view scoped) const {
  const auto it = integer_constants_.find(scoped);
  return it == integer_constants_.end() ? std::nullopt : std::optional<std::int64_t>(it->second);
}

bool TypeTable::has_type(std::string_view scoped) const {
  return struct_index_.count(scoped) != 0 || enum_index_.count(scoped) != 0;
}

const StructDef* TypeTable::find_struct(std::string_view scoped_name) const {
  if (scoped_name.substr(0, 2) == "::") {
    scoped_name.remove_prefix(2);
  }
  const auto it = struct_index_.find(scoped_name);
  return it == struct_index_.end() ? nullptr : &structs_[it->second];
}

const EnumDef* TypeTable::find_enum(std::string_view scoped_name) const {
  if (scoped_name.substr(0, 2) == "::") {
    scoped_name.remove_prefix(2);
  }
  const auto it = enum_index_.find(scoped_name);
  return it == enum_index_.end() ? nullptr : &enums_[it->second];
}

const StructDef& TypeTable::get_struct(std::string_view scoped_name) const {
  if (const StructDef* s = find_struct(scoped_name)) {
    return *s;
  }
  std::string known;
  for (const auto& s : structs_) {
    known += (known.empty() ? "" : ", ") + s.name;
  }
  throw SchemaError("unknown type '" + std::string(scoped_name) + "' (known: " + known + ")");
}

std::vector<std::string> TypeTable::struct_names() const {
  std::vector<std::string> out;
  out.reserve(structs_.size());
  for (const auto& s : structs_) {
    out.push_back(s.name);
  }
  return out;
}

TypeTable TypeTable::from_sources(const std::map<std::string, std::string>& files) {
  TypeTable table;
  std::set<std::string> done;
  std::vector<std::string> stack;
  for (const auto& [name, text] : files) {
    (void)text;
    parse_file(name, files, table, done, stack);
  }
  return table;
}

namespace {
/// Every *.idl file of `dir` by file name, added to `files`; false when `dir` cannot be opened.
bool read_idl_files(const std::string& dir, std::map<std::string, std::string>& files) {
  DIR* d = ::opendir(dir.c_str());
  if (d == nullptr) {
    return false;
  }
  while (const dirent* e = ::readdir(d)) {
    const std::string name = e->d_name;
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".idl") == 0) {
      std::ifstream in(dir + "/" + name, std::ios::binary);
      std::ostringstream text;
      text << in.rdbuf();
      if (!in) {
        ::closedir(d);
        throw SchemaError("cannot read " + dir + "/" + name);
      }
      files[name] = text.str();
    }
  }
  ::closedir(d);
  return true;
}
}  // namespace

TypeTable TypeTable::from_directory(const std::string& dir) {
  std::map<std::string, std::string> files;
  if (!read_idl_files(dir, files)) {
    throw SchemaError("cannot open IDL directory '" + dir + "'");
  }
  read_idl_files(dir + "/ros2", files);  // the ROS 2 types of idl/ros2, when there (docs/ROS2.md)
  if (files.empty()) {
    throw SchemaError("no .idl files in '" + dir + "'");
  }
  return from_sources(files);
}

const TypeTable& TypeTable::builtin() {
  static const TypeTable table = [] {
    const char* env = std::getenv("POISE_IDL_DIR");
    if (env != nullptr && *env != '\0') {
      return from_directory(env);
    }
    return from_sources(embedded_idl_sources());
  }();
  return table;
}

// ---------------------------------------------------------------------------------------------
// Sizes

std::size_t TypeTable::max_size(const TypeSpec& t, std::size_t offset) const {
  constexpr std::uint32_t kUnboundedString = 255;     // fastddsgen 2.3's assumption
  constexpr std::uint32_t kUnboundedSequence = 100;   // idem
  switch (t.kind) {
    case TypeSpec::Kind::kPrimitive: {
      const std::size_t s = primitive_size(t.primitive);
      return offset + align(offset, s) + s;
    }
    case TypeSpec::Kind::kEnum:
      return offset + align(offset, 4) + 4;
    case TypeSpec::Kind::kString:
      return offset + align(offset, 4) + 4 + (t.bound == 0 ? kUnboundedString : t.bound) + 1;
    case TypeSpec::Kind::kSequence: {
      std::size_t o = offset + align(offset, 4) + 4;
      const std::uint32_t n = t.bound == 0 ? kUnboundedSequence : t.bound;
      for (std::uint32_t i = 0; i < n; ++i) {
        o = max_size(*t.element, o);
      }
      return o;
    }
    case TypeSpec::Kind::kArray: {
      std::size_t o = offset;
      for (std::uint32_t i = 0; i < t.bound; ++i) {
        o = max_size(*t.element, o);
      }
      return o;
    }
    case TypeSpec::Kind::kStruct: {
      std::size_t o = offset;
      for (const auto& m : get_struct(t.name).members) {
        o = max_size(m.type, o);
      }
      return o;
    }
  }
  return offset;
}

std::size_t TypeTable::max_serialized_size(std::string_view scoped_name) const {
  TypeSpec t;
  t.kind = TypeSpec::Kind::kStruct;
  t.name = get_struct(scoped_name).name;
  return max_size(t, 0);
}

std::size_t TypeTable::key_max_size(const StructDef& s, std::size_t offset) const {
  std::size_t o = offset;
  for (const auto& m : s.members) {
    if (!m.key) {
      continue;
    }
    if (m.type.kind == TypeSpec::Kind::kStruct) {
      const StructDef& inner = get_struct(m.type.name);
      o = inner.has_key() ? key_max_size(inner, o) : max_size(m.type, o);
    } else {
      o = max_size(m.type, o);
    }
  }
  return o;
}

std::size_t TypeTable::key_max_serialized_size(std::string_view scoped_name) const {
  return key_max_size(get_struct(scoped_name), 0);
}

// ---------------------------------------------------------------------------------------------
// flatten

namespace {

std::vector<std::string> split_scoped(const std::string& name) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t p = name.find("::", start);
    parts.push_back(name.substr(start, p == std::string::npos ? std::string::npos : p - start));
    if (p == std::string::npos) {
      return parts;
    }
    start = p + 2;
  }
}

std::string module_of(const std::string& scoped) {
  const std::size_t p = scoped.rfind("::");
  return p == std::string::npos ? std::string() : scoped.substr(0, p);
}

}  // namespace

// not split: one depth-first walk that collects the types a struct needs and prints them in
// dependency order inside their modules.
std::string TypeTable::flatten(std::string_view scoped_name) const {
  const StructDef& root = get_struct(scoped_name);

  // Every struct / enum the root depends on (itself included).
  std::set<std::string> needed;
  std::function<void(const TypeSpec&)> visit_type;
  std::function<void(const StructDef&)> visit_struct = [&](const StructDef& s) {
    if (!needed.insert(s.name).second) {
      return;
    }
    for (const auto& m : s.members) {
      visit_type(m.type);
    }
  };
  visit_type = [&](const TypeSpec& t) {
    if (t.kind == TypeSpec::Kind::kStruct) {
      visit_struct(get_struct(t.name));
    } else if (t.kind == TypeSpec::Kind::kEnum) {
      needed.insert(t.name);
    } else if (t.element) {
      visit_type(*t.element);
    }
  };
  visit_struct(root);

  std::ostringstream out;
  std::vector<std::string> open;  // currently open module path
  const auto indent = [&open]() { return std::string(2 * open.size(), ' '); };
  const auto enter = [&](const std::string& scoped) {
    const std::vector<std::string> parts = split_scoped(scoped);
    const std::vector<std::string> path(parts.begin(), parts.end() - 1);
    std::size_t common = 0;
    while (common < open.size() && common < path.size() && open[common] == path[common]) {
      ++common;
    }
    while (open.size() > common) {
      open.pop_back();
      out << indent() << "};\n";
    }
    while (open.size() < path.size()) {
      out << indent() << "module " << path[open.size()] << " {\n";
      open.push_back(path[open.size()]);
    }
    return parts.back();
  };

  std::function<std::string(const TypeSpec&, const std::string&)> spell =
      [&](const TypeSpec& t, const std::string& current_module) -> std::string {
    switch (t.kind) {
      case TypeSpec::Kind::kPrimitive:
        return primitive_name(t.primitive);
      case TypeSpec::Kind::kString:
        return t.bound == 0 ? "string" : "string<" + std::to_string(t.bound) + ">";
      case TypeSpec::Kind::kStruct:
      case TypeSpec::Kind::kEnum:
        return module_of(t.name) == current_module ? split_scoped(t.name).back() : t.name;
      case TypeSpec::Kind::kSequence:
        return "sequence<" + spell(*t.element, current_module) +
               (t.bound == 0 ? std::string() : ", " + std::to_string(t.bound)) + ">";
      case TypeSpec::Kind::kArray:
        return spell(*t.element, current_module);  // dimensions follow the member name
    }
    return "?";
  };

  for (const auto& d : order_) {
    if (d.is_struct) {
      const StructDef& s = structs_[d.index];
      if (needed.count(s.name) == 0) {
        continue;
      }
      const std::string simple = enter(s.name);
      const std::string module = module_of(s.name);
      out << indent() << "struct " << simple << " {\n";
      for (const auto& m : s.members) {
        const TypeSpec* base = &m.type;
        std::string dims;
        while (base->kind == TypeSpec::Kind::kArray) {
          dims += "[" + std::to_string(base->bound) + "]";
          base = base->element.get();
        }
        out << indent() << "  " << (m.key ? "@key " : "") << spell(*base, module) << " " << m.name
            << dims << ";\n";
      }
      out << indent() << "};\n";
    } else {
      const EnumDef& e = enums_[d.index];
      if (needed.count(e.name) == 0) {
        continue;
      }
      const std::string simple = enter(e.name);
      out << indent() << "enum " << simple << " {\n";
      for (std::size_t i = 0; i < e.enumerators.size(); ++i) {
        out << indent() << "  " << e.enumerators[i] << (i + 1 < e.enumerators.size() ? "," : "")
            << "\n";
      }
      out << indent() << "};\n";
    }
  }
  while (!open.empty()) {
    open.pop_back();
    out << indent() << "};\n";
  }
  return out.str();
}

}  // namespace poise::schema
