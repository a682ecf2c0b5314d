// The pbrt-v4 reader's materials and textures: the materials of Material and
// MakeNamedMaterial (diffuse, conductor, dielectric, thindielectric, diffusetransmission,
// coateddiffuse, coatedconductor, mix; the others approximated as diffuse) resolved to what
// tuile's BSDFs read (spectra to linear RGB, roughness to Trowbridge-Reitz alphas), Texture
// definitions -- spectrum (imagemap, constant, scale, mix, checkerboard) as TexDefs and float
// (imagemap, constant, scale, mix, checkerboard) as FloatTexDefs -- recorded while parsing
// (loader_textures.cpp), and at the end their values set into the material fields that use
// them (bake_materials: SpectrumFix, FloatFix).
#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "bsdf/hair.h"
#include "lexer.h"
#include "loader_state.h"
#include "params.h"
#include "util.h"

namespace tuile::pbrt {

// A "texture reflectance" parameter: the TexDef index, or an error naming the texture.
int Loader::reflectance_texture(Lexer&, const Param& p) {
  if (p.strs.size() != 1) p.fail("parameter \"texture " + p.name + "\" has " + std::to_string(p.count()) + " values", "1 texture name");
  auto it = textures_.find(p.strs[0]);
  if (it != textures_.end()) return it->second;
  if (float_textures_.count(p.strs[0]))
    p.fail("texture \"" + p.strs[0] + "\" is a float texture", "a spectrum texture for " + p.name);
  p.fail("unknown texture \"" + p.strs[0] + "\"", "a name defined by Texture before its use");
}

// pbrt-v4's named spectra that are refractive indices (util/spectrum.cpp: metal-*-eta/k,
// glass-*), as tuile uses them: linear sRGB (conductor eta and k) and the value at 550 nm
// (a dielectric's eta). Derived once, offline, from the tables of pbrt-v4's
// src/pbrt/util/spectrum.cpp (mmp/pbrt-v4 at 5f7a6068) with the method of
// unbounded_spectrum_rgb (util.h): D65-weighted CIE 1931 (Wyman et al. fit) integration at
// 1 nm over 360..830 nm, XYZ to linear sRGB, each channel divided by the constant 1's.
// Tiny negative values (MgO and TiO2 k) are clamped to 0 when read.
struct NamedSpectrum {
  const char* name;
  float r, g, b;
  float at550;
};
static const NamedSpectrum named_spectra[] = {
    {"metal-Ag-eta", 0.128427f, 0.123528f, 0.150882f, 0.124777f},
    {"metal-Ag-k", 4.054051f, 3.291666f, 2.391447f, 3.339600f},
    {"metal-Al-eta", 1.400204f, 0.929958f, 0.583756f, 0.958569f},
    {"metal-Al-k", 7.725633f, 6.609999f, 5.359810f, 6.686968f},
    {"metal-Au-eta", 0.084692f, 0.401523f, 1.561496f, 0.350409f},
    {"metal-Au-k", 3.379563f, 2.508803f, 1.770199f, 2.714063f},
    {"metal-Cu-eta", 0.109572f, 0.975436f, 1.205131f, 0.958162f},
    {"metal-Cu-k", 3.261362f, 2.597568f, 2.368913f, 2.577065f},
    {"metal-CuZn-eta", 0.420815f, 0.518423f, 1.123046f, 0.527000f},
    {"metal-CuZn-k", 3.655826f, 2.686849f, 1.770408f, 2.765000f},
    {"metal-MgO-eta", 1.733812f, 1.740892f, 1.753548f, 1.740468f},
    {"metal-MgO-k", 0.0f, 0.0f, 0.0f, 0.0f},
    {"metal-TiO2-eta", 2.861729f, 2.955728f, 3.185504f, 2.954974f},
    {"metal-TiO2-k", 0.000092f, 0.0f, 0.000553f, 0.0f},
    {"glass-BK7", 1.514609f, 1.518771f, 1.525992f, 1.518537f},
    {"glass-BAF10", 1.666212f, 1.673456f, 1.686639f, 1.673051f},
    {"glass-FK51A", 1.484982f, 1.487967f, 1.493097f, 1.487796f},
    {"glass-LASF9", 1.843265f, 1.856525f, 1.881816f, 1.855809f},
    {"glass-F5", 1.667208f, 1.677646f, 1.697698f, 1.677089f},
    {"glass-F10", 1.721583f, 1.734298f, 1.759067f, 1.733574f},
    {"glass-F11", 1.776746f, 1.791907f, 1.821846f, 1.791119f},
};

static const NamedSpectrum& named_spectrum(const Param& p) {
  for (const NamedSpectrum& n : named_spectra)
    if (p.strs[0] == n.name) return n;
  std::string all;
  for (const NamedSpectrum& n : named_spectra) all += std::string(all.empty() ? "" : ", ") + n.name;
  p.fail("unknown named spectrum \"" + p.strs[0] + "\" for \"" + p.name + "\"", "one of " + all);
}

// (lambda, value) pairs: increasing wavelengths, non-negative values.
static void check_pairs(const Param& p) {
  for (size_t i = 0; i < p.nums.size(); i += 2)
    if (p.nums[i + 1] < 0 || (i > 0 && p.nums[i] < p.nums[i - 2]))
      p.fail("spectrum '" + p.name + "' has a negative value or decreasing wavelengths", "increasing wavelengths and non-negative values");
}

static Rgb clamp0(Rgb c) { return {std::max(c.r, 0.f), std::max(c.g, 0.f), std::max(c.b, 0.f)}; }

// pbrt-v4's ConductorMaterial given a reflectance: eta = 1, k = 2 sqrt(r) / sqrt(1 - r), r
// clamped to [0, 0.9999].
static Rgb k_from_reflectance(Rgb r) {
  auto k = [](float x) {
    const double c = std::clamp(double(x), 0.0, 0.9999);
    return float(2 * std::sqrt(c) / std::sqrt(1 - c));
  };
  return {k(r.r), k(r.g), k(r.b)};
}

int Loader::float_texture_ref(const Param& p) {
  if (p.strs.size() != 1) p.fail("parameter \"texture " + p.name + "\" has " + std::to_string(p.count()) + " values", "1 texture name");
  auto it = float_textures_.find(p.strs[0]);
  if (it != float_textures_.end()) return it->second;
  if (textures_.count(p.strs[0])) p.fail("texture \"" + p.strs[0] + "\" is a spectrum texture", "a float texture for " + p.name);
  p.fail("unknown float texture \"" + p.strs[0] + "\"", "a name defined by Texture \"NAME\" \"float\" before its use");
}

bool Loader::constant_float(int fd, float& v, int depth) const {
  if (fd < 0 || depth > 64) return false;
  const FloatTexDef& d = float_defs_[size_t(fd)];
  float a = 0, b = 0, w = 0;
  switch (d.kind) {
    case FloatTexDef::constant: v = d.value; return true;
    case FloatTexDef::product:
      if (!constant_float(d.a, a, depth + 1) || !constant_float(d.b, b, depth + 1)) return false;
      v = a * b;
      return true;
    case FloatTexDef::mix:
      if (!constant_float(d.a, a, depth + 1) || !constant_float(d.b, b, depth + 1) || !constant_float(d.amount, w, depth + 1))
        return false;
      v = (1 - w) * a + w * b;
      return true;
    case FloatTexDef::checker:
      if (!constant_float(d.a, a, depth + 1) || !constant_float(d.b, b, depth + 1) || a != b) return false;
      v = a;
      return true;
    default: return false;
  }
}

// Checks a constant for a material's float field and stores it (roughness through
// RoughnessToAlpha = sqrt when remap_roughness). Errors name the parameter.
void Loader::set_float(Material& m, FloatFix::Field field, float v, const std::string& file, int line, int col,
                       const std::string& name) {
  if (!std::isfinite(v))  // a float texture's product that overflowed
    fail(file, line, col, "\"" + name + "\" is not finite (its texture's values overflow a float)", "a finite value");
  switch (field) {
    case FloatFix::alpha_u:
    case FloatFix::alpha_v:
    case FloatFix::base_alpha_u:
    case FloatFix::base_alpha_v: {
      if (v < 0) fail(file, line, col, "roughness \"" + name + "\" is negative (" + std::to_string(v) + ")", "a roughness >= 0");
      const float alpha = m.remap_roughness ? std::sqrt(v) : v;
      FloatParam& f = field == FloatFix::alpha_u ? m.alpha_u
                      : field == FloatFix::alpha_v ? m.alpha_v
                      : field == FloatFix::base_alpha_u ? m.base_alpha_u
                                                        : m.base_alpha_v;
      f = {alpha, -1};
      break;
    }
    case FloatFix::mix_amount: m.mix_amount = {v, -1}; break;
    case FloatFix::displacement: {
      FloatTexture t;
      t.name = name;
      t.width = t.height = 1;
      t.value = {v};
      m.displacement = add_float_texture(std::move(t));
      break;
    }
    case FloatFix::thickness:
      if (v < 0) fail(file, line, col, "\"" + name + "\" is negative (" + std::to_string(v) + ")", "a thickness >= 0");
      m.thickness = v;
      break;
    case FloatFix::g: m.g = std::clamp(v, -1.f, 1.f); break;  // pbrt-v4 clamps g
    case FloatFix::shape_alpha: break;  // a shape's (set_shape_alpha)
  }
}

// A float parameter pbrt lets a texture give ("float NAME" or "texture NAME"): a constant is
// stored at once, a texture when textures are resolved. Returns whether it was given.
bool Loader::float_param(Params& ps, const std::string& name, Material& m, int material, FloatFix::Field field) {
  const Param* p = ps.get(name, "float|texture");
  if (!p) return false;
  if (p->type == "float") {
    if (p->nums.size() != 1) p->fail("parameter \"float " + name + "\" has " + std::to_string(p->nums.size()) + " values", "1 value");
    set_float(m, field, float(p->nums[0]), p->file, p->line, p->col, name);
    return true;
  }
  FloatFix f;
  f.field = field;
  f.material = material;
  f.def = float_texture_ref(*p);
  f.file = p->file;
  f.name = name;
  f.line = p->line;
  f.col = p->col;
  float_fixes_.push_back(f);
  return true;
}

// An unbounded spectrum given as rgb (non-negative), (lambda, value) pairs or one of pbrt's
// named spectra, to linear RGB.
static Rgb unbounded_rgb(const Param& p) {
  if (p.type == "rgb") {
    if (!(p.nums[0] >= 0 && p.nums[1] >= 0 && p.nums[2] >= 0))
      p.fail("parameter \"rgb " + p.name + "\" has a negative value", "non-negative values");
    return {float(p.nums[0]), float(p.nums[1]), float(p.nums[2])};
  }
  if (!p.nums.empty()) {
    check_pairs(p);
    return clamp0(unbounded_spectrum_rgb(p.nums.data(), p.nums.size() / 2));
  }
  const NamedSpectrum& n = named_spectrum(p);
  return clamp0({n.r, n.g, n.b});
}

// An unbounded spectrum (eta, k): unbounded_rgb, or a spectrum texture resolved at the end.
bool Loader::unbounded_param(Lexer& lx, Params& ps, const std::string& name, int material, SpectrumFix::Field field,
                             const std::string& where, Rgb& out) {
  const Param* p = ps.get(name, "rgb|spectrum|texture");
  if (!p) return false;
  if (p->type == "texture") spectrum_fixes_.push_back({field, material, reflectance_texture(lx, *p), 1, where});
  else out = unbounded_rgb(*p);
  return true;
}

// A dielectric's (or a coat's) index of refraction: a float, or a spectrum taken at 550 nm
// (tuile renders RGB: no dispersion). pbrt-v4 reads an eta of 0 as 1.
float Loader::eta_param(Params& ps, const std::string& name, const std::string& where) {
  const Param* p = ps.get(name, "float|spectrum|rgb");
  if (!p) return 1.5f;
  double v = 1.5;
  bool dispersive = false;
  if (p->type == "float") {
    if (p->nums.size() != 1) p->fail("parameter \"float " + name + "\" has " + std::to_string(p->nums.size()) + " values", "1 value");
    v = p->nums[0];
  } else if (p->type == "rgb") {
    v = p->nums[1];
    dispersive = p->nums[0] != p->nums[1] || p->nums[1] != p->nums[2];
  } else if (!p->nums.empty()) {
    check_pairs(*p);
    v = spectrum_at(p->nums.data(), p->nums.size() / 2, 550);
    for (size_t i = 3; i < p->nums.size(); i += 2) dispersive = dispersive || p->nums[i] != p->nums[1];
  } else {
    v = named_spectrum(*p).at550;
    dispersive = true;
  }
  if (v < 0) p->fail("index of refraction \"" + name + "\" is negative", "a positive index of refraction");
  if (dispersive)
    warn("dispersion", where + ": a spectrally varying \"" + name + "\" is rendered without dispersion (its value at 550 nm)");
  return v == 0 ? 1.f : float(v);
}

// pbrt-v4's mix: two named materials and an amount. tuile's mixes choose between two
// materials that are not mixes: a mix of mixes with constant amounts becomes the
// distribution over its leaf materials, exact when it has at most two.
void Loader::make_mix(Lexer& lx, const Token& t, Params& ps, const std::string& where, Material& m, int index) {
  const Param* mp = ps.get("materials", "string");
  if (!mp) lx.fail(t, "material \"mix\" without \"materials\"", "a \"string materials\" parameter with 2 names");
  if (mp->strs.size() != 2)
    mp->fail("parameter \"string materials\" has " + std::to_string(mp->strs.size()) + " values", "the names of 2 materials");
  int e[2] = {-1, -1};
  for (int i = 0; i < 2; ++i) {
    auto it = named_materials_.find(mp->strs[size_t(i)]);
    if (it == named_materials_.end())
      mp->fail("unknown named material \"" + mp->strs[size_t(i)] + "\" in mix", "a name defined by MakeNamedMaterial");
    if (scene.materials[size_t(it->second)].interface)
      mp->fail("material \"" + mp->strs[size_t(i)] + "\" is an \"interface\"", "materials that are not \"interface\" in a mix");
    e[i] = it->second;
  }
  const bool nested = scene.materials[size_t(e[0])].mix[0] >= 0 || scene.materials[size_t(e[1])].mix[0] >= 0;
  if (!nested) {
    m.mix[0] = e[0];
    m.mix[1] = e[1];
    m.mix_amount = {0.5f, -1};
    const size_t before = float_fixes_.size();
    float_param(ps, "amount", m, index, FloatFix::mix_amount);
    if (float_fixes_.size() > before) mix_amount_def_[index] = float_fixes_.back().def;
    return;
  }
  // The leaves of each entry with their probabilities (entries that are mixes are flat).
  bool textured = false;
  auto amount_of = [&](int mat) {
    auto it = mix_amount_def_.find(mat);
    float a = scene.materials[size_t(mat)].mix_amount.value;
    if (it != mix_amount_def_.end() && !constant_float(it->second, a)) {
      textured = true;
      a = 0.5f;
    }
    return std::clamp(a, 0.f, 1.f);
  };
  float amount = 0.5f;
  if (const Param* ap = ps.get("amount", "float|texture")) {
    if (ap->type == "float") {
      if (ap->nums.size() != 1) ap->fail("parameter \"float amount\" has " + std::to_string(ap->nums.size()) + " values", "1 value");
      amount = float(ap->nums[0]);
    } else if (!constant_float(float_texture_ref(*ap), amount)) {
      textured = true;
      amount = 0.5f;
    }
  }
  amount = std::clamp(amount, 0.f, 1.f);
  std::vector<std::pair<int, double>> leaves;
  auto add = [&](int mat, double p) {
    if (p <= 0) return;
    for (auto& l : leaves)
      if (l.first == mat) {
        l.second += p;
        return;
      }
    leaves.push_back({mat, p});
  };
  for (int i = 0; i < 2; ++i) {
    const double p = i == 0 ? 1.0 - amount : amount;
    const Material& x = scene.materials[size_t(e[i])];
    if (x.mix[0] < 0) {
      add(e[i], p);
    } else {
      const float a = amount_of(e[i]);
      add(x.mix[0], p * (1 - a));
      add(x.mix[1], p * a);
    }
  }
  if (leaves.empty()) leaves.push_back({e[0], 1.0});
  bool approximated = textured;
  if (leaves.size() > 2) {
    std::stable_sort(leaves.begin(), leaves.end(), [](auto& a, auto& b) { return a.second > b.second; });
    leaves.resize(2);
    approximated = true;
  }
  if (leaves.size() == 1) leaves.push_back(leaves[0]);
  m.mix[0] = leaves[0].first;
  m.mix[1] = leaves[1].first;
  const double total = leaves[0].second + leaves[1].second;
  m.mix_amount = {leaves[0].first == leaves[1].first ? 0.f : float(leaves[1].second / total), -1};
  if (approximated) {
    m.approximated_from = "mix";
    warn("material:mixnested", where + ": a \"mix\" of mixes " +
                                   std::string(textured ? "with a textured amount (0.5 used)" : "of more than two materials") +
                                   " approximated by a mix of its two most likely materials");
  }
}

// pbrt-v4's "hair" (HairMaterial): the interior's absorption from sigma_a, else from
// reflectance (Chiang et al.'s inversion, which depends on beta_n), else from eumelanin and
// pheomelanin concentrations (default: eumelanin 1.3, brown hair); eta 1.55, beta_m and
// beta_n 0.3 (in [0, 1]), alpha 2 degrees. Textured parameters: the default, with a warning.
void Loader::make_hair(Params& ps, const std::string& where, Material& m) {
  m.kind = MaterialKind::hair;
  auto textured = [&](const Param* p) {
    if (!p || p->type != "texture") return false;
    warn("hair:texture", where + ": a texture as the hair's \"" + p->name + "\" is not supported: its default used");
    return true;
  };
  auto number = [&](const char* name, float def, float lo, float hi) {
    const Param* p = ps.get(name, "float|texture");
    if (!p || textured(p)) return def;
    const double v = p->nums.empty() ? def : p->nums[0];
    if (!(v >= lo && v <= hi))
      p->fail("\"" + std::string(name) + "\" is " + std::to_string(v),
              "a value in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
    return float(v);
  };
  m.eta = number("eta", 1.55f, 1e-3f, 100.f);
  m.beta_m = number("beta_m", 0.3f, 0.f, 1.f);
  m.beta_n = number("beta_n", 0.3f, 0.f, 1.f);
  m.hair_alpha = number("alpha", 2.f, -90.f, 90.f);
  const Param* sa = ps.get("sigma_a", "rgb|spectrum|texture");
  const Param* refl = ps.get("reflectance", "rgb|spectrum|texture");
  if (!refl) refl = ps.get("color", "rgb|spectrum|texture");
  const Param* eu = ps.get("eumelanin", "float|texture");
  const Param* ph = ps.get("pheomelanin", "float|texture");
  if (sa && !textured(sa)) {
    m.hair_sigma_a = unbounded_rgb(*sa);
    return;
  }
  if (refl && !textured(refl)) {
    Rgb c{0.5f, 0.5f, 0.5f};
    if (refl->type == "rgb") c = {float(refl->nums[0]), float(refl->nums[1]), float(refl->nums[2])};
    else ps.spectrum(refl->name, false, c);
    if (!(c.r >= 0 && c.g >= 0 && c.b >= 0)) refl->fail("the hair's reflectance has a negative value", "values in [0, 1]");
    auto one = [&](float v) { return hair_sigma_a_from_reflectance(std::clamp(v, 0.f, 1.f), m.beta_n); };
    m.hair_sigma_a = {one(c.r), one(c.g), one(c.b)};
    return;
  }
  auto concentration = [&](const Param* p, float def) {
    if (!p || textured(p)) return def;
    const double v = p->nums.empty() ? def : p->nums[0];
    if (!std::isfinite(v)) p->fail("a melanin concentration is not a number", "a finite value");
    return float(std::max(v, 0.0));
  };
  const bool melanin = (eu && eu->type != "texture") || (ph && ph->type != "texture");
  const float ce = concentration(eu, melanin ? 0.f : 1.3f), cp = concentration(ph, 0.f);
  // pbrt-v4's SigmaAFromConcentration: eumelanin's and pheomelanin's absorption (RGB)
  m.hair_sigma_a = {ce * 0.419f + cp * 0.187f, ce * 0.697f + cp * 0.4f, ce * 1.37f + cp * 1.05f};
}

// pbrt-v4's measured media (Jensen et al. 2001; Narasimhan et al. 2006): sigma_s' and
// sigma_a in mm^-1, RGB, the values pbrt-v4's GetMediumScatteringProperties gives.
namespace {
struct MediumPreset {
  const char* name;
  Rgb sigma_s, sigma_a;
};
const MediumPreset medium_presets[] = {
    {"Apple", {2.29f, 2.39f, 1.97f}, {0.0030f, 0.0034f, 0.046f}},
    {"Chicken1", {0.15f, 0.21f, 0.38f}, {0.015f, 0.077f, 0.19f}},
    {"Chicken2", {0.19f, 0.25f, 0.32f}, {0.018f, 0.088f, 0.20f}},
    {"Cream", {7.38f, 5.47f, 3.15f}, {0.0002f, 0.0028f, 0.0163f}},
    {"Ketchup", {0.18f, 0.07f, 0.03f}, {0.061f, 0.97f, 1.45f}},
    {"Marble", {2.19f, 2.62f, 3.00f}, {0.0021f, 0.0041f, 0.0071f}},
    {"Potato", {0.68f, 0.70f, 0.55f}, {0.0024f, 0.0090f, 0.12f}},
    {"Skimmilk", {0.70f, 1.22f, 1.90f}, {0.0014f, 0.0025f, 0.0142f}},
    {"Skin1", {0.74f, 0.88f, 1.01f}, {0.032f, 0.17f, 0.48f}},
    {"Skin2", {1.09f, 1.59f, 1.79f}, {0.013f, 0.070f, 0.145f}},
    {"Spectralon", {11.6f, 20.4f, 14.9f}, {0.00f, 0.00f, 0.00f}},
    {"Wholemilk", {2.55f, 3.21f, 3.77f}, {0.0011f, 0.0024f, 0.014f}},
    {"Lowfat Milk", {0.89187f, 1.5136f, 2.532f}, {0.002875f, 0.00575f, 0.0115f}},
    {"Reduced Milk", {2.4858f, 3.1669f, 4.5214f}, {0.0025556f, 0.0051111f, 0.012778f}},
    {"Regular Milk", {4.5513f, 5.8294f, 7.136f}, {0.0015333f, 0.0046f, 0.019933f}},
    {"Espresso", {0.72378f, 0.84557f, 1.0247f}, {4.7984f, 6.5751f, 8.8493f}},
    {"Mint Mocha Coffee", {0.31602f, 0.38538f, 0.48131f}, {3.772f, 5.8228f, 7.82f}},
    {"Lowfat Soy Milk", {0.30576f, 0.34233f, 0.61664f}, {0.0014375f, 0.0071875f, 0.035937f}},
    {"Regular Soy Milk", {0.59223f, 0.73866f, 1.4693f}, {0.0019167f, 0.0095833f, 0.065167f}},
    {"Lowfat Chocolate Milk", {0.64925f, 0.83916f, 1.1057f}, {0.0115f, 0.0368f, 0.1564f}},
    {"Regular Chocolate Milk", {1.4585f, 2.1289f, 2.9527f}, {0.010063f, 0.043125f, 0.14375f}},
    {"Coke", {8.9053e-05f, 8.372e-05f, 0.f}, {0.10014f, 0.16503f, 0.2468f}},
    {"Pepsi", {6.1697e-05f, 4.2564e-05f, 0.f}, {0.091641f, 0.14158f, 0.20729f}},
    {"Sprite", {6.0306e-06f, 6.4139e-06f, 6.5504e-06f}, {0.001886f, 0.0018308f, 0.0020025f}},
    {"Gatorade", {0.0024574f, 0.003007f, 0.0037325f}, {0.024794f, 0.019289f, 0.008878f}},
    {"Chardonnay", {1.7982e-05f, 1.3758e-05f, 1.2023e-05f}, {0.010782f, 0.011855f, 0.023997f}},
    {"White Zinfandel", {1.7501e-05f, 1.9069e-05f, 1.288e-05f}, {0.012072f, 0.016184f, 0.019843f}},
    {"Merlot", {2.1129e-05f, 0.f, 0.f}, {0.11632f, 0.25191f, 0.29434f}},
    {"Budweiser Beer", {2.4356e-05f, 2.4079e-05f, 1.0564e-05f}, {0.011492f, 0.024911f, 0.057786f}},
    {"Coors Light Beer", {5.0922e-05f, 4.301e-05f, 0.f}, {0.006164f, 0.013984f, 0.034983f}},
    {"Clorox", {0.0024035f, 0.0031373f, 0.003991f}, {0.0033542f, 0.014892f, 0.026297f}},
    {"Apple Juice", {0.00013612f, 0.00015836f, 0.000227f}, {0.012957f, 0.023741f, 0.052184f}},
    {"Cranberry Juice", {0.00010402f, 0.00011646f, 7.8139e-05f}, {0.039437f, 0.094223f, 0.12426f}},
    {"Grape Juice", {5.382e-05f, 0.f, 0.f}, {0.10404f, 0.23958f, 0.29325f}},
    {"Ruby Grapefruit Juice", {0.011002f, 0.010927f, 0.011036f}, {0.085867f, 0.18314f, 0.25262f}},
    {"White Grapefruit Juice", {0.22826f, 0.23998f, 0.32748f}, {0.0138f, 0.018831f, 0.056781f}},
    {"Shampoo", {0.0007176f, 0.0008303f, 0.0009016f}, {0.014107f, 0.045693f, 0.061717f}},
    {"Strawberry Shampoo", {0.00015671f, 0.00015947f, 1.518e-05f}, {0.01449f, 0.05796f, 0.075823f}},
    {"Head & Shoulders Shampoo", {0.023805f, 0.028804f, 0.034306f}, {0.084621f, 0.15688f, 0.20365f}},
    {"Lemon Tea Powder", {0.040224f, 0.045264f, 0.051081f}, {2.4288f, 4.5757f, 7.2127f}},
    {"Orange Powder", {0.00015617f, 0.00017482f, 0.0001762f}, {0.001449f, 0.003441f, 0.007863f}},
    {"Pink Lemonade Powder", {0.00012103f, 0.00013073f, 0.00012528f}, {0.001165f, 0.002366f, 0.003195f}},
    {"Cappuccino Powder", {1.8436f, 2.5851f, 2.1662f}, {35.844f, 49.547f, 61.084f}},
    {"Salt Powder", {0.027333f, 0.032451f, 0.031979f}, {0.28415f, 0.3257f, 0.34148f}},
    {"Sugar Powder", {0.00022272f, 0.00025513f, 0.000271f}, {0.012638f, 0.031051f, 0.050124f}},
    {"Suisse Mocha Powder", {2.7979f, 3.5452f, 4.3365f}, {17.502f, 27.004f, 35.433f}},
    {"Pacific Ocean Surface Water", {0.0001764f, 0.00032095f, 0.00019617f}, {0.031845f, 0.031324f, 0.030147f}},
};
}  // namespace

// MakeNamedMedium: pbrt-v4's homogeneous medium (preset, else sigma_a and sigma_s, 1 by
// default; scale; g; Le and Lescale); grid, cloud and nanovdb media are named in a warning
// and kept without their data. A medium is parsed, listed by `tuile info` and bound to its
// shapes; the renderer does not render media yet (the warning says so).
void Loader::make_medium(Lexer& lx, const Token& t, const std::string& name, Params& ps) {
  const std::string where = loc_str(lx, t);
  if (named_media_.count(name)) lx.fail(t, "medium \"" + name + "\" redefined", "a name not given to another MakeNamedMedium");
  Medium md;
  md.name = name;
  md.where = where;
  md.type = ps.one_string("type", "");
  if (md.type.empty()) lx.fail(t, "MakeNamedMedium \"" + name + "\" without a \"string type\"", "\"string type\" \"homogeneous\"");
  if (md.type == "uniformgrid" || md.type == "rgbgrid" || md.type == "cloud" || md.type == "nanovdb") {
    ps.mark_all_used();
    warn("mediumtype:" + md.type, where + ": medium type \"" + md.type + "\" is not supported: the shapes it fills render without it");
  } else if (md.type != "homogeneous") {
    lx.fail(t, "unknown medium type \"" + md.type + "\"", "homogeneous, uniformgrid, rgbgrid, cloud or nanovdb");
  } else {
    md.supported = true;
    auto coefficient = [&](const char* pname, Rgb& out) {
      if (const Param* p = ps.get(pname, "rgb|spectrum")) out = unbounded_rgb(*p);
    };
    bool from_preset = false;
    const std::string preset = ps.one_string("preset", "");
    if (!preset.empty()) {
      for (const MediumPreset& mp : medium_presets)
        if (preset == mp.name) {
          md.sigma_a = mp.sigma_a;
          md.sigma_s = mp.sigma_s;
          md.preset = preset;
          from_preset = true;
        }
      if (!from_preset) warn("mediumpreset:" + preset, where + ": medium preset \"" + preset + "\" not found: sigma_a and sigma_s used");
    }
    if (!from_preset) {
      coefficient("sigma_a", md.sigma_a);
      coefficient("sigma_s", md.sigma_s);
    } else {
      ps.get("sigma_a", "rgb|spectrum");
      ps.get("sigma_s", "rgb|spectrum");
    }
    const float scale = ps.one_float("scale", 1);
    if (!(scale >= 0) || !std::isfinite(scale)) ps.get("scale", "float")->fail("\"scale\" is negative or not finite", "a finite scale >= 0");
    md.sigma_a = mul(md.sigma_a, scale);
    md.sigma_s = mul(md.sigma_s, scale);
    if (!finite_rgb(md.sigma_a) || !finite_rgb(md.sigma_s))
      lx.fail(t, "the medium's sigma_a or sigma_s times \"scale\" is not finite", "coefficients whose product with scale fits a float");
    md.g = ps.one_float("g", 0);
    if (!(md.g > -1 && md.g < 1)) ps.get("g", "float")->fail("\"g\" is " + std::to_string(md.g), "an asymmetry in (-1, 1)");
    if (ps.get("Le", "rgb|blackbody|spectrum")) ps.spectrum("Le", true, md.Le);
    const float le_scale = ps.one_float("Lescale", 1);
    if (!(le_scale >= 0) || !std::isfinite(le_scale))
      ps.get("Lescale", "float")->fail("\"Lescale\" is negative or not finite", "a finite scale >= 0");
    md.Le = mul(md.Le, le_scale);
    if (!emission_in_range(md.Le)) lx.fail(t, "the medium's Le times \"Lescale\" is not finite or above 1e30", "an emission whose product with Lescale fits a float");
  }
  warn_unused(ps, "MakeNamedMedium", lx, t);
  named_media_[name] = int(scene.media.size());
  scene.media.push_back(md);
}

int Loader::make_material(Lexer& lx, const Token& t, const std::string& type, Params& ps) {
  const std::string where = loc_str(lx, t);
  const int index = int(scene.materials.size());
  Material m;
  auto spectrum_fix = [&](SpectrumFix::Field f, const Param& p, float scale = 1) {
    spectrum_fixes_.push_back({f, index, reflectance_texture(lx, p), scale, where});
  };
  // A spectrum a texture may give (reflectance, transmittance, albedo): rgb, blackbody or
  // (lambda, value) pairs; named spectra are not reflectances tuile knows (default kept).
  auto albedo = [&](const char* name, SpectrumFix::Field f, Rgb& out, float scale = 1) {
    const Param* p = ps.get(name, "rgb|blackbody|spectrum|texture");
    if (!p) return false;
    if (p->type == "texture") spectrum_fix(f, *p, scale);
    else if (!ps.spectrum(name, false, out))
      warn("namedspectrum:" + std::string(name), where + ": the named spectrum \"" + p->strs[0] + "\" as \"" + name +
                                                     "\" is not supported: the default used");
    return true;
  };
  // roughness / uroughness / vroughness (with a prefix for coatedconductor), default 0.
  auto roughness = [&](const std::string& prefix, FloatFix::Field fu, FloatFix::Field fv) {
    if (!float_param(ps, prefix + "uroughness", m, index, fu) && !float_param(ps, prefix + "roughness", m, index, fu))
      set_float(m, fu, 0, "", 0, 0, prefix + "roughness");
    if (!float_param(ps, prefix + "vroughness", m, index, fv) && !float_param(ps, prefix + "roughness", m, index, fv))
      set_float(m, fv, 0, "", 0, 0, prefix + "roughness");
  };
  auto surface = [&] {  // parameters every pbrt-v4 surface material takes
    float_param(ps, "displacement", m, index, FloatFix::displacement);
    if (ps.get("normalmap", "string")) warn("normalmap", where + ": normal maps (\"normalmap\") are not supported and were ignored");
  };
  auto layer = [&] {  // coated*: the medium between coat and base
    if (!float_param(ps, "thickness", m, index, FloatFix::thickness)) m.thickness = 0.01f;
    albedo("albedo", SpectrumFix::albedo, m.albedo);
    if (float_param(ps, "g", m, index, FloatFix::g) && !(m.g > -1 && m.g < 1)) {  // (a constant: a texture's is read later)
      const Param* gp = ps.get("g", "float|texture");
      if (gp && gp->type == "float") gp->fail("\"g\" is " + std::to_string(m.g), "an asymmetry in (-1, 1)");
    }
    m.max_depth = ps.one_int("maxdepth", 10);
    m.nsamples = ps.one_int("nsamples", 1);
    if (m.max_depth < 0) ps.get("maxdepth", "integer")->fail("\"maxdepth\" is negative", "a depth >= 0");
    if (m.nsamples < 1) ps.get("nsamples", "integer")->fail("\"nsamples\" is less than 1", "at least 1 sample");
  };
  // A conductor's eta and k, or its reflectance (pbrt-v4: not both); default copper.
  auto conductor = [&](const std::string& prefix) {
    const bool has_eta = unbounded_param(lx, ps, prefix + "eta", index, SpectrumFix::eta, where, m.eta_rgb);
    const bool has_k = unbounded_param(lx, ps, prefix + "k", index, SpectrumFix::k, where, m.k_rgb);
    const Param* rp = ps.get("reflectance", "rgb|blackbody|spectrum|texture");
    if (rp && (has_eta || has_k))
      rp->fail("both \"reflectance\" and \"" + prefix + "eta\"/\"" + prefix + "k\" given", "either a reflectance or eta and k");
    if (rp) {
      Rgb r{0.5f, 0.5f, 0.5f};
      albedo("reflectance", SpectrumFix::conductor_reflectance, r);
      m.eta_rgb = {1, 1, 1};
      m.k_rgb = k_from_reflectance(r);
      return;
    }
    const NamedSpectrum& cu_eta = named_spectra[6];
    const NamedSpectrum& cu_k = named_spectra[7];
    if (!has_eta) m.eta_rgb = {cu_eta.r, cu_eta.g, cu_eta.b};
    if (!has_k) m.k_rgb = {cu_k.r, cu_k.g, cu_k.b};
  };
  if (type == "diffuse") {
    albedo("reflectance", SpectrumFix::reflectance, m.reflectance);
    surface();
  } else if (type == "conductor") {
    m.kind = MaterialKind::conductor;
    m.remap_roughness = ps.one_bool("remaproughness", true);
    conductor("");
    roughness("", FloatFix::alpha_u, FloatFix::alpha_v);
    surface();
  } else if (type == "dielectric" || type == "thindielectric") {
    m.kind = type == "dielectric" ? MaterialKind::dielectric : MaterialKind::thin_dielectric;
    m.eta = eta_param(ps, "eta", where);
    if (type == "dielectric") {
      m.remap_roughness = ps.one_bool("remaproughness", true);
      roughness("", FloatFix::alpha_u, FloatFix::alpha_v);
    }
    surface();
  } else if (type == "diffusetransmission") {
    m.kind = MaterialKind::diffuse_transmission;
    const float scale = ps.one_float("scale", 1);
    if (scale < 0) ps.get("scale", "float")->fail("\"scale\" is negative", "a scale >= 0");
    m.reflectance = m.transmittance = {0.25f, 0.25f, 0.25f};
    albedo("reflectance", SpectrumFix::reflectance, m.reflectance, scale);
    albedo("transmittance", SpectrumFix::transmittance, m.transmittance, scale);
    m.reflectance = mul(m.reflectance, scale);
    m.transmittance = mul(m.transmittance, scale);
    surface();
  } else if (type == "coateddiffuse") {
    m.kind = MaterialKind::coated_diffuse;
    m.remap_roughness = ps.one_bool("remaproughness", true);
    albedo("reflectance", SpectrumFix::reflectance, m.reflectance);
    roughness("", FloatFix::alpha_u, FloatFix::alpha_v);
    m.eta = eta_param(ps, "eta", where);
    layer();
    surface();
  } else if (type == "coatedconductor") {
    m.kind = MaterialKind::coated_conductor;
    m.remap_roughness = ps.one_bool("remaproughness", true);
    roughness("interface.", FloatFix::alpha_u, FloatFix::alpha_v);
    m.eta = eta_param(ps, "interface.eta", where);
    conductor("conductor.");
    roughness("conductor.", FloatFix::base_alpha_u, FloatFix::base_alpha_v);
    layer();
    surface();
  } else if (type == "hair") {
    make_hair(ps, where, m);
  } else if (type == "interface" || type == "none" || type.empty()) {
    // (pbrt-v4 makes no material for all three: rays pass its shapes, which only bound
    // media; their shapes are left out of the geometry: Loader::flatten)
    m.interface = true;
    if (type != "interface")
      warn("material:none", where + ": Material \"" + type + "\" is deprecated (pbrt-v4): read as \"interface\", whose shapes "
                                    "rays pass");
  } else if (type == "mix") {
    make_mix(lx, t, ps, where, m, index);
  } else {
    const bool found = albedo("reflectance", SpectrumFix::reflectance, m.reflectance) ||
                       (ps.get("Kd", "rgb|spectrum|texture") && albedo("Kd", SpectrumFix::reflectance, m.reflectance));
    m.approximated_from = type;
    ps.mark_all_used();
    warn("material:" + type, where + ": material \"" + type + "\" approximated as diffuse (" +
                                 (found ? "its reflectance" : "grey 0.5") + ")");
  }
  warn_unused(ps, "Material \"" + type + "\"", lx, t);
  scene.materials.push_back(m);
  return index;
}

void Loader::bake_materials() {
  static const char* const spectrum_field_names[] = {"reflectance", "transmittance", "albedo", "eta", "k", "reflectance"};
  for (const SpectrumFix& f : spectrum_fixes_) {
    const Resolved r = resolve(f.def);
    Material& m = scene.materials[size_t(f.material)];
    const bool texturable = f.field == SpectrumFix::reflectance || f.field == SpectrumFix::transmittance;
    if (r.image && texturable) {
      int tex = r.texture;
      if (f.scale != 1) {
        auto key = std::make_pair(tex, f.scale);
        auto it = scaled_textures_.find(key);
        if (it == scaled_textures_.end()) {
          Texture t = scene.textures[size_t(tex)];
          for (float& v : t.rgb) v *= f.scale;
          scene.textures.push_back(std::move(t));
          it = scaled_textures_.emplace(key, int(scene.textures.size() - 1)).first;
        }
        tex = it->second;
      }
      (f.field == SpectrumFix::reflectance ? m.texture : m.transmittance_texture) = tex;
      continue;
    }
    Rgb v = r.value;
    if (r.image) {
      v = average(scene.textures[size_t(r.texture)]);
      const std::string what = std::string(material_kind_names[int(m.kind)]) + " " + spectrum_field_names[f.field];
      warn("texavg:" + what, f.where + ": a texture as the " + what + " is not supported: its average used");
    }
    v = mul(v, f.scale);
    switch (f.field) {
      case SpectrumFix::reflectance: m.reflectance = v; break;
      case SpectrumFix::transmittance: m.transmittance = v; break;
      case SpectrumFix::albedo: m.albedo = v; break;
      case SpectrumFix::eta: m.eta_rgb = clamp0(v); break;
      case SpectrumFix::k: m.k_rgb = clamp0(v); break;
      case SpectrumFix::conductor_reflectance:
        m.eta_rgb = {1, 1, 1};
        m.k_rgb = k_from_reflectance(v);
        break;
    }
  }
  for (const FloatFix& f : float_fixes_) {
    const ResolvedFloat r = resolve_float(f.def);
    if (f.field == FloatFix::shape_alpha) {
      set_shape_alpha(f, r);
      continue;
    }
    Material& m = scene.materials[size_t(f.material)];
    if (!r.image) {
      set_float(m, f.field, r.value, f.file, f.line, f.col, f.name);
      continue;
    }
    switch (f.field) {
      case FloatFix::alpha_u: m.alpha_u = {0, r.texture}; break;
      case FloatFix::alpha_v: m.alpha_v = {0, r.texture}; break;
      case FloatFix::base_alpha_u: m.base_alpha_u = {0, r.texture}; break;
      case FloatFix::base_alpha_v: m.base_alpha_v = {0, r.texture}; break;
      case FloatFix::mix_amount: m.mix_amount = {0.5f, r.texture}; break;
      case FloatFix::displacement: m.displacement = r.texture; break;
      case FloatFix::shape_alpha: break;  // above
      case FloatFix::thickness:
      case FloatFix::g:
        warn("texavg:" + f.name, f.file + ":" + std::to_string(f.line) + ": a texture as \"" + f.name +
                                     "\" of a coated material is not supported: its average used");
        set_float(m, f.field, average(scene.float_textures[size_t(r.texture)]), f.file, f.line, f.col, f.name);
        break;
    }
  }
}

}  // namespace tuile::pbrt