// Tokens of the pbrt-v4 text format: directive names, quoted strings, numbers, brackets.
// Comments run from '#' to the end of the line. Every token knows its line and column.
#pragma once
#include <string>
#include <string_view>

namespace tuile::pbrt {

enum class Tok { eof, word, number, string, lbracket, rbracket };

struct Token {
  Tok kind = Tok::eof;
  std::string_view text;  // strings: between the quotes, escapes not yet processed
  int line = 1, col = 1;
};

class Lexer {
 public:
  // file names the source in messages; dir resolves its relative file names.
  Lexer(std::string text, std::string file, std::string dir);
  Token next();
  const Token& peek();
  const std::string& file() const { return file_; }
  const std::string& dir() const { return dir_; }
  [[noreturn]] void fail(const Token& at, const std::string& message, const std::string& expected) const;

 private:
  Token scan();
  std::string text_, file_, dir_;
  size_t pos_ = 0;
  int line_ = 1;
  size_t line_start_ = 0;
  Token peeked_;
  bool has_peek_ = false;
};

// Processes \n \t \\ \" ... escapes of a string token.
std::string unescape(std::string_view s);
// A short printable form of a token for messages.
std::string describe(const Token& t);

}  // namespace tuile::pbrt
