#include "chaincomp/yaml_strict.hpp"

#include <yaml-cpp/eventhandler.h>

#include <sys/stat.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <fstream>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <utility>
#include <vector>

namespace chaincomp {

namespace {

// yamlsource.py's limits, with its messages.
constexpr int kMaxDepth = 64;
constexpr long kMaxExpansion = 10, kSlack = 10000;

// PyYAML's implicit resolvers (yaml/resolver.py), verbatim.
const std::regex kBool("yes|Yes|YES|no|No|NO|true|True|TRUE|false|False|FALSE|on|On|ON|off|Off|OFF");
const std::regex kInt(
    "[-+]?0b[0-1_]+|[-+]?0[0-7_]+|[-+]?(?:0|[1-9][0-9_]*)|[-+]?0x[0-9a-fA-F_]+|[-+]?[1-9][0-9_]*(?::[0-5]?[0-9])+");
const std::regex kFloat(
    "[-+]?(?:[0-9][0-9_]*)\\.[0-9_]*(?:[eE][-+][0-9]+)?|\\.[0-9][0-9_]*(?:[eE][-+][0-9]+)?"
    "|[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\\.[0-9_]*|[-+]?\\.(?:inf|Inf|INF)|\\.(?:nan|NaN|NAN)");
// What both YAML versions read as the same number: plain decimals without leading zeros,
// underscores or base-60, and YAML's .inf and .nan.
const std::regex kPlainDecimal(
    "[-+]?(?:(?:0|[1-9][0-9]*)(?:\\.[0-9]*)?|\\.[0-9]+)(?:[eE][-+]?[0-9]+)?|[-+]?\\.(?:inf|Inf|INF)|\\.(?:nan|NaN|NAN)");

Yaml11 resolve_plain(const std::string& s) {
  if (s.empty() || s == "~" || s == "null" || s == "Null" || s == "NULL") return Yaml11::kNull;
  if (std::regex_match(s, kBool)) return Yaml11::kBool;
  if (std::regex_match(s, kInt)) return Yaml11::kInt;
  if (std::regex_match(s, kFloat)) return Yaml11::kFloat;
  return Yaml11::kStr;
}

std::string py_str_repr(const std::string& s) {
  const char q = s.find('\'') != std::string::npos && s.find('"') == std::string::npos ? '"' : '\'';
  std::string out(1, q);
  for (unsigned char c : s) {
    if (c == '\\' || c == q) out += '\\', out += static_cast<char>(c);
    else if (c == '\n') out += "\\n";
    else if (c == '\t') out += "\\t";
    else if (c == '\r') out += "\\r";
    else if (c < 0x20 || c == 0x7f) {
      char buf[5];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else out += static_cast<char>(c);
  }
  return out + q;
}

struct Refusal {
  int line;
  std::string message;
};

// Walks the parser's events as PyYAML's composer and constructor walk the document, and
// refuses what yamlsource.py refuses, in the same order: while composing (depth, tags,
// anchors), then the alias expansion, then while constructing (keys, ambiguous numbers).
class Checker : public YAML::EventHandler {
 public:
  struct Node {
    int line;
    std::vector<int> children;
  };
  std::vector<Node> nodes;
  int documents = 0, second_document_line = 0;
  bool have_construct_error = false;
  Refusal construct_error{0, ""};

  void OnDocumentStart(const YAML::Mark& mark) override {
    if (++documents == 2) second_document_line = mark.line + 1;
  }
  void OnDocumentEnd() override {}
  void OnNull(const YAML::Mark& mark, YAML::anchor_t anchor) override { scalar(mark, "?", anchor, "", true); }
  void OnAlias(const YAML::Mark& mark, YAML::anchor_t anchor) override {
    enter(mark);
    if (open_anchors_.count(anchor)) throw Refusal{mark.line + 1, "a YAML alias refers to a node that contains it"};
    const int id = anchors_.at(anchor);
    add_child(id, mark.line + 1, nullptr);
    --depth_;
  }
  void OnScalar(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t anchor,
                const std::string& value) override {
    scalar(mark, tag, anchor, value, false);
  }
  void OnSequenceStart(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t anchor,
                       YAML::EmitterStyle::value) override {
    open(mark, tag, anchor, false);
  }
  void OnSequenceEnd() override { close(); }
  void OnMapStart(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t anchor,
                  YAML::EmitterStyle::value) override {
    open(mark, tag, anchor, true);
  }
  void OnMapEnd() override { close(); }
  void OnAnchor(const YAML::Mark& mark, const std::string& name) override {
    if (!anchor_names_.insert(name).second) {
      throw Refusal{mark.line + 1, "duplicate YAML anchor " + py_str_repr(name)};
    }
  }

 private:
  struct Open {
    int id;
    bool is_map;
    bool expect_key = true;
    std::set<std::pair<bool, std::string>> keys;  // (is text, text)
    YAML::anchor_t anchor;
  };
  std::vector<Open> stack_;
  std::map<YAML::anchor_t, int> anchors_;
  std::set<YAML::anchor_t> open_anchors_;
  std::set<std::string> anchor_names_;
  int depth_ = 0;

  void enter(const YAML::Mark& mark) {
    if (++depth_ > kMaxDepth) throw Refusal{mark.line + 1, "nested more than 64 levels deep"};
  }
  static void check_tag(const YAML::Mark& mark, const std::string& tag) {
    if (tag != "?" && tag != "!" && !tag.empty()) {
      throw Refusal{mark.line + 1, "YAML tags are not accepted (" + tag + ")"};
    }
  }
  void construct_fail(int line, const std::string& message) {
    if (!have_construct_error) construct_error = {line, message};
    have_construct_error = true;
  }
  // Records node `id` as the next child of the open collection; a key is checked as the
  // constructor checks it. `key_text`: the key's text when it is a scalar.
  void add_child(int id, int line, const std::pair<bool, std::string>* key_text) {
    if (stack_.empty()) return;
    Open& top = stack_.back();
    nodes[top.id].children.push_back(id);
    if (!top.is_map) return;
    if (top.expect_key) {
      if (key_text == nullptr) {
        construct_fail(line, "a mapping key must be text or a number, not a list or mapping");
      } else if (key_text->first && key_text->second == "<<") {
        construct_fail(line, "YAML merge keys (<<) are not accepted");
      } else if (!top.keys.insert(*key_text).second) {
        construct_fail(line, key_text->second + ": duplicate key " +
                                 (key_text->first ? py_str_repr(key_text->second) : key_text->second));
      }
    }
    top.expect_key = !top.expect_key;
  }
  void scalar(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t anchor, const std::string& value,
              bool is_null) {
    enter(mark);
    check_tag(mark, tag);
    const int id = static_cast<int>(nodes.size());
    nodes.push_back({mark.line + 1, {}});
    if (anchor) anchors_[anchor] = id;
    const Yaml11 kind = is_null ? Yaml11::kNull : tag == "?" ? resolve_plain(value) : Yaml11::kStr;
    if ((kind == Yaml11::kInt || kind == Yaml11::kFloat) && !std::regex_match(value, kPlainDecimal)) {
      construct_fail(mark.line + 1, "ambiguous number " + py_str_repr(value) +
                                        ": YAML 1.1 and 1.2 read it differently; write it in plain decimal");
    }
    // keys compare as PyYAML's constructed values do: text apart from numbers, null, booleans
    const std::pair<bool, std::string> key{kind == Yaml11::kStr, is_null ? "None" : value};
    add_child(id, mark.line + 1, &key);
    --depth_;
  }
  void open(const YAML::Mark& mark, const std::string& tag, YAML::anchor_t anchor, bool is_map) {
    enter(mark);
    check_tag(mark, tag);
    const int id = static_cast<int>(nodes.size());
    nodes.push_back({mark.line + 1, {}});
    if (anchor) {
      anchors_[anchor] = id;
      open_anchors_.insert(anchor);
    }
    stack_.push_back({id, is_map, true, {}, anchor});
  }
  void close() {
    const Open done = std::move(stack_.back());
    stack_.pop_back();
    open_anchors_.erase(done.anchor);
    --depth_;
    add_child(done.id, nodes[done.id].line, nullptr);
  }
};

// yamlsource._check_expansion, step for step (the same traversal, so the same node is named).
bool check_expansion(const std::vector<Checker::Node>& nodes, const std::string& path, std::string& error) {
  if (nodes.empty()) return true;
  const long written = static_cast<long>(nodes.size());
  const long limit = kMaxExpansion * written + kSlack;
  std::vector<long> size(nodes.size(), -1), depth(nodes.size(), 0);
  std::vector<std::pair<int, bool>> stack{{0, false}};
  while (!stack.empty()) {
    const auto [id, done] = stack.back();
    stack.pop_back();
    if (size[id] >= 0) continue;
    if (!done) {
      stack.push_back({id, true});
      for (int c : nodes[id].children) {
        if (size[c] < 0) stack.push_back({c, false});
      }
      continue;
    }
    long s = 1, d = 0;
    for (int c : nodes[id].children) {
      s = std::min(s + size[c], limit + 1);
      d = std::max(d, depth[c]);
    }
    size[id] = s;
    depth[id] = d + 1;
    if (s > limit) {
      error = path + ":" + std::to_string(nodes[id].line) + ": aliases expand the document beyond " +
              std::to_string(limit) + " nodes (" + std::to_string(written) + " written)";
      return false;
    }
    if (depth[id] > kMaxDepth) {
      error = path + ":" + std::to_string(nodes[id].line) + ": nested more than 64 levels deep (aliases expanded)";
      return false;
    }
  }
  return true;
}

// yamlsource.read_text and PyYAML's reader: UTF-8, and only the characters YAML allows (a
// NUL byte also sent yaml-cpp 0.7 allocating without end: found by fuzz/fuzz_params).
bool check_text(const std::string& path, const std::string& text, std::string& error) {
  if (text.size() > kMaxFileBytes) {
    error = path + ": larger than 16 MiB";
    return false;
  }
  const auto* p = reinterpret_cast<const unsigned char*>(text.data());
  const std::size_t n = text.size();
  int line = 1;
  for (std::size_t i = 0; i < n;) {
    const unsigned char c = p[i];
    const int len = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xe ? 3 : (c >> 3) == 0x1e ? 4 : 0;
    std::uint32_t cp = len == 1 ? c : len == 2 ? c & 0x1f : len == 3 ? c & 0x0f : c & 0x07;
    bool ok = len > 0 && i + len <= n;
    for (int k = 1; ok && k < len; ++k) {
      ok = (p[i + k] & 0xc0) == 0x80;
      cp = (cp << 6) | (p[i + k] & 0x3f);
    }
    // no overlong forms, surrogates or code points past U+10FFFF (Python's strict decoder)
    ok = ok && !(len == 2 && cp < 0x80) && !(len == 3 && cp < 0x800) && !(len == 4 && cp < 0x10000) &&
         !(cp >= 0xd800 && cp <= 0xdfff) && cp <= 0x10ffff;
    if (!ok) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "%#04x", c);
      error = path + ":" + std::to_string(line) + ": not UTF-8 text (byte " + buf + ")";
      return false;
    }
    const bool printable = cp == 0x9 || cp == 0xa || cp == 0xd || (cp >= 0x20 && cp <= 0x7e) || cp == 0x85 ||
                           (cp >= 0xa0 && cp <= 0xd7ff) || (cp >= 0xe000 && cp <= 0xfffd) || cp >= 0x10000;
    if (!printable) {
      char buf[16];
      std::snprintf(buf, sizeof buf, "%04x", static_cast<unsigned>(cp));
      error = path + ":" + std::to_string(line) + ": YAML syntax error: unacceptable character #x" + buf +
              ": special characters are not allowed";
      return false;
    }
    line += cp == '\n';
    i += static_cast<std::size_t>(len);
  }
  return true;
}

// A parser's message on one line: control characters written as escapes.
std::string one_line(const std::string& msg) {
  std::string out;
  for (unsigned char c : msg) {
    if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out;
}

}  // namespace

bool read_input_file(const std::string& path, std::string& text, std::string& error) {
  struct stat st {};
  if (stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    error = path + ": not a regular file";
    return false;
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    error = path + ": cannot read file: " + std::strerror(errno);
    return false;
  }
  // one byte past the limit tells a file too large (it may have grown since stat)
  text.assign(kMaxFileBytes + 1, '\0');
  in.read(&text[0], static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (text.size() > kMaxFileBytes) {
    error = path + ": larger than " + std::to_string(kMaxFileBytes >> 20) + " MiB";
    return false;
  }
  return true;
}

bool load_strict_yaml(const std::string& path, const std::string& text, YAML::Node& doc, std::string& error) {
  if (!check_text(path, text, error)) return false;
  Checker check;
  try {
    std::istringstream in(text);
    YAML::Parser parser(in);
    // a second document is refused, so two are enough: past that, yaml-cpp 0.7 can return a
    // document without end on some broken text (fuzz/fuzz_config)
    for (int i = 0; i < 2 && parser.HandleNextDocument(check); ++i) {
    }
  } catch (const Refusal& r) {
    error = path + ":" + std::to_string(r.line) + ": " + r.message;
    return false;
  } catch (const YAML::Exception& e) {
    error = path + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + one_line(e.msg);
    return false;
  } catch (const std::exception& e) {  // std::out_of_range: an alias yaml-cpp let through undefined
    error = path + ": YAML syntax error: " + one_line(e.what());
    return false;
  }
  if (check.documents > 1) {
    error = path + ":" + std::to_string(check.second_document_line) + ": YAML syntax error: but found another document";
    return false;
  }
  if (!check_expansion(check.nodes, path, error)) return false;
  if (check.have_construct_error) {
    error = path + ":" + std::to_string(check.construct_error.line) + ": " + check.construct_error.message;
    return false;
  }
  try {
    doc = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    error = path + ":" + std::to_string(e.mark.line + 1) + ": YAML syntax error: " + one_line(e.msg);
    return false;
  }
  return true;
}

Yaml11 resolve(const YAML::Node& n) {
  if (!n.IsDefined() || n.IsNull()) return Yaml11::kNull;
  if (!n.IsScalar()) return Yaml11::kCollection;
  return n.Tag() == "?" ? resolve_plain(n.Scalar()) : Yaml11::kStr;
}

std::string py_float_repr(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, std::fabs(v), std::chars_format::scientific);
  const std::string sci(buf, r.ptr);  // d.ddde±XX
  const std::size_t e = sci.find('e');
  std::string digits = sci.substr(0, e);
  if (digits.size() > 1) digits.erase(1, 1);  // drop the point
  const int exp = std::atoi(sci.c_str() + e + 1);
  const int decpt = exp + 1;
  std::string out = std::signbit(v) ? "-" : "";
  if (decpt > 16 || decpt < -3) {
    out += digits.substr(0, 1) + (digits.size() > 1 ? "." + digits.substr(1) : "");
    char ebuf[16];
    std::snprintf(ebuf, sizeof ebuf, "e%c%02d", exp < 0 ? '-' : '+', std::abs(exp));
    return out + ebuf;
  }
  if (decpt <= 0) return out + "0." + std::string(-decpt, '0') + digits;
  if (decpt >= static_cast<int>(digits.size())) return out + digits + std::string(decpt - digits.size(), '0') + ".0";
  return out + digits.substr(0, decpt) + "." + digits.substr(decpt);
}

bool yaml_number(const YAML::Node& n, double& out) {
  const Yaml11 k = resolve(n);
  if (k != Yaml11::kInt && k != Yaml11::kFloat) return false;
  std::string s = n.Scalar();
  const std::size_t dot = s.find('.');
  if (dot != std::string::npos && dot + 1 < s.size() && std::isalpha(static_cast<unsigned char>(s[dot + 1]))) {
    const bool neg = s[0] == '-';
    out = s.back() == 'n' || s.back() == 'N' ? NAN : neg ? -INFINITY : INFINITY;  // .nan, .NaN, .NAN
    return true;
  }
  out = std::strtod(s.c_str(), nullptr);  // a plain decimal (load_strict_yaml refused the rest)
  return true;
}

std::string py_repr(const YAML::Node& n) {
  switch (resolve(n)) {
    case Yaml11::kNull: return "None";
    case Yaml11::kBool: return std::string("yYtTo").find(n.Scalar()[0]) != std::string::npos &&
                                       n.Scalar() != "off" && n.Scalar() != "Off" && n.Scalar() != "OFF"
                                   ? "True"
                                   : "False";
    case Yaml11::kInt: {
      std::string s = n.Scalar();
      if (s[0] == '+') s.erase(0, 1);
      if (s == "-0") s = "0";
      return s;
    }
    case Yaml11::kFloat: {
      double v = 0;
      yaml_number(n, v);
      return py_float_repr(v);
    }
    case Yaml11::kStr: break;
    case Yaml11::kCollection: return describe(n);
  }
  return py_str_repr(n.Scalar());
}

// A number with an exponent that YAML 1.1 takes for text (1e3, 1.5e3, 1e+3: it wants a dot and
// a signed exponent) -> the spelling it reads as that number (1.0e+3); "" for other text. As
// chaincomp/model/yamlsource.py's yaml11_number, so that both loaders' messages carry the same hint.
std::string yaml11_number(const std::string& s) {
  static const std::regex re("([-+]?)([0-9]*)(\\.?)([0-9]*)[eE]([-+]?)([0-9]+)");
  std::smatch m;   // libstdc++'s regex recurses per character: a hint only for number-sized text
  if (s.size() > 64 || !std::regex_match(s, m, re) || (m.length(2) == 0 && m.length(4) == 0)) return "";
  if (m.length(3) > 0 && m.length(5) > 0) return "";   // 1.0e+3 is text only when quoted
  return m.str(1) + m.str(2) + "." + (m.length(4) > 0 ? m.str(4) : m.length(2) > 0 ? "0" : "") + "e" +
         (m.length(5) > 0 ? m.str(5) : "+") + m.str(6);
}

std::string describe(const YAML::Node& n) {
  if (!n.IsDefined() || n.IsNull()) return "nothing";
  if (n.IsMap()) return "a mapping";
  if (n.IsSequence()) return "a list of " + std::to_string(n.size()) + (n.size() == 1 ? " item" : " items");
  if (resolve(n) == Yaml11::kStr) {
    const std::string number = yaml11_number(n.Scalar());
    if (!number.empty()) {
      return "str " + py_repr(n) + " (YAML reads " + n.Scalar() + " as text: write " + number + ")";
    }
  }
  static const char* const names[] = {"NoneType", "bool", "int", "float", "str"};
  return std::string(names[static_cast<int>(resolve(n))]) + " " + py_repr(n);
}

}  // namespace chaincomp
