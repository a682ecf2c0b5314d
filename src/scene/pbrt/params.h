// Parameter lists of pbrt-v4 directives ("float fov" [ 45 ]): parsed and checked for
// type and count when read, looked up by name and type when a directive uses them.
#pragma once
#include <string>
#include <vector>

#include "lexer.h"
#include "scene/scene.h"

namespace tuile::pbrt {

struct Param {
  std::string type, name;  // type normalised: point -> point3, normal -> normal3, color -> rgb
  std::string file;
  int line = 0, col = 0;
  std::vector<double> nums;
  std::vector<std::string> strs;
  std::vector<bool> bools;
  bool used = false;
  size_t count() const { return nums.size() + strs.size() + bools.size(); }
  [[noreturn]] void fail(const std::string& message, const std::string& expected) const;
};

struct Params {
  std::vector<Param> items;
  // Finds a parameter by name; a different type than `type` (one of several separated
  // by '|') is an error. Marks it used.
  const Param* get(const std::string& name, const char* type);
  float one_float(const std::string& name, float def);
  int one_int(const std::string& name, int def);
  bool one_bool(const std::string& name, bool def);
  std::string one_string(const std::string& name, const std::string& def);
  // A point3 or vector3 with exactly one value.
  bool one_point(const std::string& name, double out[3]);
  // Emission (normalised like pbrt-v4) or reflectance from rgb/blackbody/spectrum.
  bool spectrum(const std::string& name, bool emission, Rgb& out);
  void mark_all_used();
};

// Reads the parameter list that follows a directive's fixed arguments.
Params read_params(Lexer& lx);
// A number token as a finite float (integers too); fails on anything else.
double parse_number(Lexer& lx, const Token& t);

}  // namespace tuile::pbrt
