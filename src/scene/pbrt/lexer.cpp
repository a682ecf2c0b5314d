// The pbrt-v4 tokenizer: tokens with their file and line for error messages.
#include "lexer.h"

#include "util.h"

namespace tuile::pbrt {

Lexer::Lexer(std::string text, std::string file, std::string dir)
    : text_(std::move(text)), file_(std::move(file)), dir_(std::move(dir)) {}

void Lexer::fail(const Token& at, const std::string& message, const std::string& expected) const {
  pbrt::fail(file_, at.line, at.col, message, expected);
}

const Token& Lexer::peek() {
  if (!has_peek_) {
    peeked_ = scan();
    has_peek_ = true;
  }
  return peeked_;
}

Token Lexer::next() {
  if (has_peek_) {
    has_peek_ = false;
    return peeked_;
  }
  return scan();
}

static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }
static bool is_delim(char c) { return is_space(c) || c == '"' || c == '[' || c == ']' || c == '#'; }

Token Lexer::scan() {
  const size_t n = text_.size();
  for (;;) {
    while (pos_ < n && is_space(text_[pos_])) {
      if (text_[pos_] == '\n') {
        ++line_;
        line_start_ = pos_ + 1;
      }
      ++pos_;
    }
    if (pos_ < n && text_[pos_] == '#') {
      while (pos_ < n && text_[pos_] != '\n') ++pos_;
      continue;
    }
    break;
  }
  Token t;
  t.line = line_;
  t.col = int(pos_ - line_start_) + 1;
  if (pos_ >= n) return t;
  const char c = text_[pos_];
  if (c == '[' || c == ']') {
    t.kind = c == '[' ? Tok::lbracket : Tok::rbracket;
    t.text = std::string_view(text_).substr(pos_, 1);
    ++pos_;
    return t;
  }
  if (c == '"') {
    const size_t start = ++pos_;
    while (pos_ < n && text_[pos_] != '"') {
      if (text_[pos_] == '\n') fail(t, "unterminated string", "a closing '\"' on the same line");
      if (text_[pos_] == '\\') {  // an escape: pbrt-v4's, anything else is an error
        if (pos_ + 1 >= n || text_[pos_ + 1] == '\n' || text_[pos_ + 1] == '\r')
          fail(t, "unterminated string (a backslash ends its line)", "a closing '\"' on the same line");
        const char e = text_[pos_ + 1];
        if (std::string_view("bfnrt\\'\"").find(e) == std::string_view::npos)
          fail(t, std::string("unknown escape '\\") + e + "' in a string", "one of \\b \\f \\n \\r \\t \\\\ \\' \\\"");
        ++pos_;
      }
      ++pos_;
    }
    if (pos_ >= n) fail(t, "unterminated string", "a closing '\"'");
    t.kind = Tok::string;
    t.text = std::string_view(text_).substr(start, pos_ - start);
    ++pos_;
    return t;
  }
  const size_t start = pos_;
  while (pos_ < n && !is_delim(text_[pos_])) ++pos_;
  t.text = std::string_view(text_).substr(start, pos_ - start);
  t.kind = (c >= '0' && c <= '9') || c == '-' || c == '+' || c == '.' ? Tok::number : Tok::word;
  return t;
}

std::string unescape(std::string_view s) {
  if (s.find('\\') == std::string_view::npos) return std::string(s);
  std::string r;
  r.reserve(s.size());
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] != '\\' || i + 1 == s.size()) {
      r += s[i];
      continue;
    }
    switch (char e = s[++i]) {
      case 'n': r += '\n'; break;
      case 't': r += '\t'; break;
      case 'r': r += '\r'; break;
      case 'b': r += '\b'; break;
      case 'f': r += '\f'; break;
      default: r += e; break;
    }
  }
  return r;
}

std::string describe(const Token& t) {
  switch (t.kind) {
    case Tok::eof: return "end of file";
    case Tok::string: {
      std::string s(t.text.substr(0, 40));
      return "\"" + s + (t.text.size() > 40 ? "...\"" : "\"");
    }
    default: {
      std::string s(t.text.substr(0, 40));
      for (char& ch : s)
        if (uint8_t(ch) < 32 || uint8_t(ch) > 126) ch = '?';
      return "'" + s + (t.text.size() > 40 ? "...'" : "'");
    }
  }
}

}  // namespace tuile::pbrt
