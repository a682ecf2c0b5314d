// Parameter lists of pbrt-v4 directives: parsing, type and count checks, lookups.
#include "params.h"

#include <cfloat>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstring>

#include "util.h"

namespace tuile::pbrt {

void Param::fail(const std::string& message, const std::string& expected) const {
  pbrt::fail(file, line, col, message, expected);
}

double parse_number(Lexer& lx, const Token& t) {
  if (t.kind != Tok::number) lx.fail(t, "unexpected " + describe(t), "a number");
  const char* b = t.text.data();
  const char* e = b + t.text.size();
  if (b < e && *b == '+') ++b;  // from_chars does not take a leading '+'
  double v = 0;
  const auto r = std::from_chars(b, e, v);
  if (r.ec == std::errc::result_out_of_range) lx.fail(t, "number " + describe(t) + " is out of range", "a finite number that fits in a float");
  if (r.ec != std::errc() || r.ptr != e) lx.fail(t, "invalid number " + describe(t), "a number");
  if (!std::isfinite(v)) lx.fail(t, "number " + describe(t) + " is not finite", "a finite number");
  if (std::abs(v) > double(FLT_MAX)) lx.fail(t, "number " + describe(t) + " is out of range", "a finite number that fits in a float");
  return v;
}

static bool is_integral_text(std::string_view s) {
  size_t i = (!s.empty() && (s[0] == '-' || s[0] == '+')) ? 1 : 0;
  if (i == s.size()) return false;
  for (; i < s.size(); ++i)
    if (s[i] < '0' || s[i] > '9') return false;
  return true;
}

static const char* normalise_type(std::string_view t) {
  static const char* const known[] = {"integer", "float",   "point2",  "vector2", "point3", "vector3", "normal3",
                                      "bool",    "string",  "texture", "rgb",     "spectrum", "blackbody"};
  for (const char* k : known)
    if (t == k) return k;
  if (t == "point") return "point3";
  if (t == "vector") return "vector3";
  if (t == "normal") return "normal3";
  if (t == "color") return "rgb";
  return nullptr;
}

static void add_value(Lexer& lx, Param& p, const Token& t, bool& integral) {
  if (t.kind == Tok::number) {
    p.nums.push_back(parse_number(lx, t));
    integral = integral && is_integral_text(t.text);
  } else if (t.kind == Tok::string) {
    if (p.type == "bool" && (t.text == "true" || t.text == "false")) p.bools.push_back(t.text == "true");
    else p.strs.push_back(unescape(t.text));
  } else if (t.kind == Tok::word && (t.text == "true" || t.text == "false")) {
    p.bools.push_back(t.text == "true");
  } else {
    lx.fail(t, "unexpected " + describe(t) + " in the value of parameter \"" + p.type + " " + p.name + "\"",
            t.kind == Tok::eof ? "']'" : "a number, a quoted string, true or false");
  }
}

static void check_param(const Param& p, bool integral) {
  const std::string decl = "\"" + p.type + " " + p.name + "\"";
  const size_t n = p.count();
  if (n == 0) p.fail("parameter " + decl + " has no values", "at least one value");
  const bool numeric = p.type == "integer" || p.type == "float" || p.type == "point2" || p.type == "vector2" ||
                       p.type == "point3" || p.type == "vector3" || p.type == "normal3" || p.type == "rgb" ||
                       p.type == "blackbody";
  if (numeric && n != p.nums.size()) p.fail("parameter " + decl + " has non-numeric values", "numbers only");
  if ((p.type == "string" || p.type == "texture") && n != p.strs.size())
    p.fail("parameter " + decl + " has non-string values", "quoted strings only");
  if (p.type == "bool" && n != p.bools.size()) p.fail("parameter " + decl + " has non-boolean values", "true or false");
  if (p.type == "integer") {
    if (!integral) p.fail("parameter " + decl + " has a non-integer value", "integers only");
    for (double v : p.nums)
      if (v < double(INT_MIN) || v > double(INT_MAX)) p.fail("parameter " + decl + " has an integer out of range", "32-bit integers");
  }
  const size_t per = p.type == "point2" || p.type == "vector2"                          ? 2
                     : p.type == "point3" || p.type == "vector3" || p.type == "normal3" ? 3
                                                                                         : 1;
  if (per > 1 && n % per != 0)
    p.fail("parameter " + decl + " has " + std::to_string(n) + " values", "a multiple of " + std::to_string(per));
  if (p.type == "rgb" && n != 3) p.fail("parameter " + decl + " has " + std::to_string(n) + " values", "3 values");
  if (p.type == "blackbody" && n != 1) p.fail("parameter " + decl + " has " + std::to_string(n) + " values", "1 value (a temperature in kelvin)");
  if (p.type == "spectrum") {
    if (!p.bools.empty() || (!p.strs.empty() && !p.nums.empty()) || p.strs.size() > 1)
      p.fail("parameter " + decl + " has mixed values", "(lambda, value) pairs or one named spectrum");
    if (!p.nums.empty() && p.nums.size() % 2 != 0)
      p.fail("parameter " + decl + " has " + std::to_string(n) + " values", "(lambda, value) pairs");
  }
}

Params read_params(Lexer& lx) {
  Params ps;
  while (lx.peek().kind == Tok::string) {
    const Token decl = lx.next();
    // "type name": exactly two words
    std::string_view s = decl.text;
    std::string_view words[3];
    int nw = 0;
    size_t i = 0;
    while (i < s.size() && nw < 3) {
      while (i < s.size() && (s[i] == ' ' || s[i] == '\t')) ++i;
      const size_t b = i;
      while (i < s.size() && s[i] != ' ' && s[i] != '\t') ++i;
      if (i > b) words[nw++] = s.substr(b, i - b);
    }
    if (nw != 2) lx.fail(decl, "malformed parameter declaration " + describe(decl), "\"TYPE NAME\" such as \"float fov\"");
    const char* type = normalise_type(words[0]);
    if (!type)
      lx.fail(decl, "unknown parameter type '" + std::string(words[0].substr(0, 40)) + "'",
              "integer, float, point2, vector2, point3, vector3, normal3, bool, string, texture, rgb, spectrum or blackbody");
    Param p;
    p.type = type;
    p.name = std::string(words[1]);
    p.file = lx.file();
    p.line = decl.line;
    p.col = decl.col;
    bool integral = true;
    const Token v = lx.next();
    if (v.kind == Tok::lbracket) {
      for (;;) {
        const Token t = lx.next();
        if (t.kind == Tok::rbracket) break;
        if (t.kind == Tok::lbracket) lx.fail(t, "nested '['", "values or ']'");
        add_value(lx, p, t, integral);
      }
    } else {
      add_value(lx, p, v, integral);
    }
    check_param(p, integral);
    ps.items.push_back(std::move(p));
  }
  return ps;
}

const Param* Params::get(const std::string& name, const char* type) {
  for (Param& p : items) {
    if (p.name != name) continue;
    // type may list alternatives: "rgb|spectrum"
    bool ok = false;
    for (const char* t = type; *t;) {
      const char* e = std::strchr(t, '|');
      const size_t len = e ? size_t(e - t) : std::strlen(t);
      if (p.type.size() == len && p.type.compare(0, len, t, len) == 0) ok = true;
      t += len + (e ? 1 : 0);
    }
    if (!ok) {
      std::string exp = type;
      for (char& c : exp)
        if (c == '|') c = '/';
      p.fail("parameter '" + name + "' has type '" + p.type + "'", "type " + exp);
    }
    p.used = true;
    return &p;
  }
  return nullptr;
}

static void expect_one(const Param& p) {
  if (p.count() != 1)
    p.fail("parameter \"" + p.type + " " + p.name + "\" has " + std::to_string(p.count()) + " values", "1 value");
}

float Params::one_float(const std::string& name, float def) {
  const Param* p = get(name, "float");
  if (!p) return def;
  expect_one(*p);
  return float(p->nums[0]);
}

int Params::one_int(const std::string& name, int def) {
  const Param* p = get(name, "integer");
  if (!p) return def;
  expect_one(*p);
  return int(p->nums[0]);
}

bool Params::one_bool(const std::string& name, bool def) {
  const Param* p = get(name, "bool");
  if (!p) return def;
  expect_one(*p);
  return p->bools[0];
}

std::string Params::one_string(const std::string& name, const std::string& def) {
  const Param* p = get(name, "string");
  if (!p) return def;
  expect_one(*p);
  return p->strs[0];
}

bool Params::one_point(const std::string& name, double out[3]) {
  const Param* p = get(name, "point3|vector3");
  if (!p) return false;
  if (p->nums.size() != 3)
    p->fail("parameter \"" + p->type + " " + p->name + "\" has " + std::to_string(p->nums.size() / 3) + " points", "1 point");
  for (int i = 0; i < 3; ++i) out[i] = p->nums[i];
  return true;
}

bool Params::spectrum(const std::string& name, bool emission, Rgb& out) {
  const Param* p = get(name, "rgb|blackbody|spectrum");
  if (!p) return false;
  if (p->type == "rgb") {
    if (p->nums[0] < 0 || p->nums[1] < 0 || p->nums[2] < 0)
      p->fail("parameter \"rgb " + name + "\" has a negative value", "non-negative values");
    out = {float(p->nums[0]), float(p->nums[1]), float(p->nums[2])};
  } else if (p->type == "blackbody") {
    if (!(p->nums[0] > 0)) p->fail("blackbody temperature must be positive", "a temperature in kelvin > 0");
    out = blackbody_rgb(p->nums[0]);
  } else if (!p->nums.empty()) {
    for (size_t i = 0; i < p->nums.size(); i += 2)
      if (p->nums[i + 1] < 0 || (i > 0 && p->nums[i] < p->nums[i - 2]))
        p->fail("spectrum '" + name + "' has a negative value or decreasing wavelengths", "increasing wavelengths and non-negative values");
    out = sampled_spectrum_rgb(p->nums.data(), p->nums.size() / 2, emission);
  } else {
    return false;  // a named spectrum: the caller decides
  }
  return true;
}

void Params::mark_all_used() {
  for (Param& p : items) p.used = true;
}

}  // namespace tuile::pbrt
