// The pbrt-v4 reader's materials and float textures: each pbrt-v4 material's parameters
// land in Material's fields (with pbrt-v4's defaults), named spectra give the documented
// RGB, roughness is remapped, mixes point at their materials, float textures are baked,
// and bad input is an error naming the file and line.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "output_files.h"
#include "scene/image_io.h"
#include "scene/pbrt.h"

namespace fs = std::filesystem;
using namespace tuile;

namespace {

// A scratch directory per test binary run, removed at exit.
const fs::path& tmp_dir() {
  static const tuile::testing::TempDir dir;
  return dir.path;
}

// An uncompressed 24-bit TGA, top row first.
void write_tga(const fs::path& p, int w, int h, const std::vector<uint8_t>& rgb) {
  std::string s(18, '\0');
  s[2] = 2;
  s[12] = char(w & 255), s[13] = char(w >> 8), s[14] = char(h & 255), s[15] = char(h >> 8);
  s[16] = 24;
  s[17] = 0x20;
  for (int i = 0; i < w * h; ++i) {
    s += char(rgb[3 * i + 2]);
    s += char(rgb[3 * i + 1]);
    s += char(rgb[3 * i]);
  }
  std::ofstream(p, std::ios::binary) << s;
}

Scene world(const std::string& body) { return load_pbrt_string("WorldBegin\n" + body, "m.pbrt", tmp_dir().string()); }

const std::string tri = "Shape \"trianglemesh\" \"point3 P\" [ 1 0 0  0 1 0  0 0 1 ]\n";

// The material of the i-th mesh.
const Material& mat(const Scene& s, size_t i) { return s.materials[size_t(s.meshes.at(i).material)]; }

// One material on one triangle.
Scene one(const std::string& material) { return world(material + "\n" + tri); }

std::string error_of(const std::string& body) {
  try {
    world(body);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "(no error)";
}

// "m.pbrt:LINE:COL" of the first occurrence of needle in "WorldBegin\n" + body.
std::string loc(const std::string& body, const std::string& needle) {
  const std::string text = "WorldBegin\n" + body;
  const size_t pos = text.find(needle);
  EXPECT_NE(pos, std::string::npos) << needle;
  int line = 1;
  size_t start = 0;
  for (size_t i = 0; i < pos; ++i)
    if (text[i] == '\n') ++line, start = i + 1;
  return "m.pbrt:" + std::to_string(line) + ":" + std::to_string(pos - start + 1);
}

void expect_error(const std::string& body, const std::string& at, const std::string& want) {
  const std::string e = error_of(body);
  EXPECT_EQ(e.rfind(loc(body, at) + ": error: ", 0), 0u) << e << "\nwanted at " << loc(body, at);
  EXPECT_NE(e.find(want), std::string::npos) << e << "\nwanted: " << want;
}

bool has_warning(const Scene& s, const std::string& what) {
  for (const auto& w : s.warnings)
    if (w.find(what) != std::string::npos) return true;
  return false;
}

void expect_rgb(Rgb c, float r, float g, float b, float tol = 1e-5f) {
  EXPECT_NEAR(c.r, r, tol);
  EXPECT_NEAR(c.g, g, tol);
  EXPECT_NEAR(c.b, b, tol);
}

// Fresnel reflectance of a conductor at normal incidence.
float f0(float eta, float k) { return ((eta - 1) * (eta - 1) + k * k) / ((eta + 1) * (eta + 1) + k * k); }

// pbrt-v4's tabulated copper (src/pbrt/util/spectrum.cpp, Cu_eta and Cu_k), as a file would give them.
const std::string cu_eta_pairs =
    "298.757050 1.400313 302.400421 1.380000 306.133759 1.358438 309.960449 1.340000 313.884003 1.329063 317.908142 1.325000 "
    "322.036835 1.332500 326.274139 1.340000 330.624481 1.334375 335.092377 1.325000 339.682678 1.317812 344.400482 1.310000 "
    "349.251221 1.300313 354.240509 1.290000 359.374420 1.281563 364.659332 1.270000 370.102020 1.249062 375.709625 1.225000 "
    "381.489777 1.200000 387.450562 1.180000 393.600555 1.174375 399.948975 1.175000 406.505493 1.177500 413.280579 1.180000 "
    "420.285339 1.178125 427.531647 1.175000 435.032196 1.172812 442.800629 1.170000 450.851562 1.165312 459.200653 1.160000 "
    "467.864838 1.155312 476.862213 1.150000 486.212463 1.142812 495.936707 1.135000 506.057861 1.131562 516.600769 1.120000 "
    "527.592224 1.092437 539.061646 1.040000 551.040771 0.950375 563.564453 0.826000 576.670593 0.645875 590.400818 0.468000 "
    "604.800842 0.351250 619.920898 0.272000 635.816284 0.230813 652.548279 0.214000 670.184753 0.209250 688.800964 0.213000 "
    "708.481018 0.216250 729.318665 0.223000 751.419250 0.236500 774.901123 0.250000 799.897949 0.254188 826.561157 0.260000 "
    "855.063293 0.280000 885.601257 0.300000";
const std::string cu_k_pairs =
    "298.757050 1.662125 302.400421 1.687000 306.133759 1.703313 309.960449 1.720000 313.884003 1.744563 317.908142 1.770000 "
    "322.036835 1.791625 326.274139 1.810000 330.624481 1.822125 335.092377 1.834000 339.682678 1.851750 344.400482 1.872000 "
    "349.251221 1.894250 354.240509 1.916000 359.374420 1.931688 364.659332 1.950000 370.102020 1.972438 375.709625 2.015000 "
    "381.489777 2.121562 387.450562 2.210000 393.600555 2.177188 399.948975 2.130000 406.505493 2.160063 413.280579 2.210000 "
    "420.285339 2.249938 427.531647 2.289000 435.032196 2.326000 442.800629 2.362000 450.851562 2.397625 459.200653 2.433000 "
    "467.864838 2.469187 476.862213 2.504000 486.212463 2.535875 495.936707 2.564000 506.057861 2.589625 516.600769 2.605000 "
    "527.592224 2.595562 539.061646 2.583000 551.040771 2.576500 563.564453 2.599000 576.670593 2.678062 590.400818 2.809000 "
    "604.800842 3.010750 619.920898 3.240000 635.816284 3.458187 652.548279 3.670000 670.184753 3.863125 688.800964 4.050000 "
    "708.481018 4.239563 729.318665 4.430000 751.419250 4.619563 774.901123 4.817000 799.897949 5.034125 826.561157 5.260000 "
    "855.063293 5.485625 885.601257 5.717000";

}  // namespace

// --- conductor ---------------------------------------------------------------------------

TEST(PbrtMaterials, ConductorDefaultsToSmoothCopper) {
  const Scene s = one("Material \"conductor\"");
  const Material& m = mat(s, 0);
  EXPECT_EQ(m.kind, MaterialKind::conductor);
  EXPECT_TRUE(m.approximated_from.empty());
  EXPECT_TRUE(m.remap_roughness);
  EXPECT_EQ(m.alpha_u.value, 0);
  EXPECT_EQ(m.alpha_v.value, 0);
  EXPECT_EQ(m.alpha_u.texture, -1);
  const Scene cu = one("Material \"conductor\" \"spectrum eta\" \"metal-Cu-eta\" \"spectrum k\" \"metal-Cu-k\"");
  expect_rgb(m.eta_rgb, mat(cu, 0).eta_rgb.r, mat(cu, 0).eta_rgb.g, mat(cu, 0).eta_rgb.b, 0);
  expect_rgb(m.k_rgb, mat(cu, 0).k_rgb.r, mat(cu, 0).k_rgb.g, mat(cu, 0).k_rgb.b, 0);
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];
}

TEST(PbrtMaterials, ConductorRgbEtaKAndRoughness) {
  const Scene s = world(
      "Material \"conductor\" \"rgb eta\" [0.2 0.9 1.1] \"rgb k\" [3.9 2.4 2.1] \"float roughness\" 0.04\n" + tri +
      "Material \"conductor\" \"float uroughness\" 0.09 \"float vroughness\" 0.25\n" + tri +
      "Material \"conductor\" \"float roughness\" 0.04 \"bool remaproughness\" false\n" + tri);
  const Material& a = mat(s, 0);
  expect_rgb(a.eta_rgb, 0.2f, 0.9f, 1.1f);
  expect_rgb(a.k_rgb, 3.9f, 2.4f, 2.1f);
  EXPECT_NEAR(a.alpha_u.value, 0.2f, 1e-6);  // RoughnessToAlpha = sqrt
  EXPECT_NEAR(a.alpha_v.value, 0.2f, 1e-6);
  EXPECT_NEAR(mat(s, 1).alpha_u.value, 0.3f, 1e-6);
  EXPECT_NEAR(mat(s, 1).alpha_v.value, 0.5f, 1e-6);
  EXPECT_FALSE(mat(s, 2).remap_roughness);
  EXPECT_NEAR(mat(s, 2).alpha_u.value, 0.04f, 1e-7);
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];
}

TEST(PbrtMaterials, ConductorReflectanceGivesEtaOneAndK) {
  const Scene s = world("Material \"conductor\" \"rgb reflectance\" [0.5 0.2 1]\n" + tri);
  const Material& m = mat(s, 0);
  expect_rgb(m.eta_rgb, 1, 1, 1);
  // pbrt-v4: k = 2 sqrt(r) / sqrt(1 - r), r clamped to [0, 0.9999]
  EXPECT_NEAR(m.k_rgb.r, 2.0f, 1e-5);
  EXPECT_NEAR(m.k_rgb.g, 2 * std::sqrt(0.2f) / std::sqrt(0.8f), 1e-5);
  EXPECT_NEAR(m.k_rgb.b, 2 * std::sqrt(0.9999) / std::sqrt(1 - 0.9999), 1e-2);
  // with eta = 1 the normal-incidence Fresnel reflectance is the reflectance given
  EXPECT_NEAR(f0(m.eta_rgb.r, m.k_rgb.r), 0.5f, 1e-5);
  EXPECT_NEAR(f0(m.eta_rgb.g, m.k_rgb.g), 0.2f, 1e-5);
}

TEST(PbrtMaterials, NamedMetalSpectra) {
  auto metal = [](const std::string& name) {
    const Scene s = one("Material \"conductor\" \"spectrum eta\" \"metal-" + name + "-eta\" \"spectrum k\" \"metal-" + name + "-k\"");
    return mat(s, 0);
  };
  const Material cu = metal("Cu"), au = metal("Au"), ag = metal("Ag"), al = metal("Al");
  // plausibility: copper and gold reflect red most (low eta, high k in red)
  EXPECT_LT(cu.eta_rgb.r, cu.eta_rgb.g);
  EXPECT_LT(cu.eta_rgb.g, cu.eta_rgb.b);
  EXPECT_GT(cu.k_rgb.r, cu.k_rgb.g);
  EXPECT_GT(cu.k_rgb.g, cu.k_rgb.b);
  EXPECT_LT(au.eta_rgb.r, au.eta_rgb.b);
  EXPECT_GT(au.k_rgb.r, au.k_rgb.b);
  // Independent check: the normal-incidence reflectance of the RGB eta/k against the
  // linear-sRGB F0 of these metals published in Real-Time Rendering (4th ed., table 9.2).
  struct F0 {
    const Material* m;
    float r, g, b;
  } ref[] = {{&cu, 0.955f, 0.638f, 0.538f}, {&au, 1.000f, 0.782f, 0.344f}, {&ag, 0.972f, 0.960f, 0.915f}, {&al, 0.913f, 0.922f, 0.924f}};
  for (const F0& x : ref) {
    EXPECT_NEAR(f0(x.m->eta_rgb.r, x.m->k_rgb.r), x.r, 0.035f);
    EXPECT_NEAR(f0(x.m->eta_rgb.g, x.m->k_rgb.g), x.g, 0.035f);
    EXPECT_NEAR(f0(x.m->eta_rgb.b, x.m->k_rgb.b), x.b, 0.035f);
  }
  // The other metals pbrt-v4 names are known too.
  for (const char* n : {"CuZn", "MgO", "TiO2"}) {
    const Material m = metal(n);
    EXPECT_GT(m.eta_rgb.g, 0) << n;
    EXPECT_GE(m.k_rgb.g, 0) << n;
  }
}

TEST(PbrtMaterials, NamedSpectraMatchTheirTablesGivenAsPairs) {
  // The constants were derived offline from pbrt-v4's tables with the method the loader
  // applies to (lambda, value) pairs: both must agree.
  const Scene s = world("Material \"conductor\" \"spectrum eta\" [ " + cu_eta_pairs + " ] \"spectrum k\" [ " + cu_k_pairs + " ]\n" +
                        tri + "Material \"conductor\" \"spectrum eta\" \"metal-Cu-eta\" \"spectrum k\" \"metal-Cu-k\"\n" + tri);
  const Material& p = mat(s, 0);
  const Material& n = mat(s, 1);
  expect_rgb(p.eta_rgb, n.eta_rgb.r, n.eta_rgb.g, n.eta_rgb.b, 2e-4f);
  expect_rgb(p.k_rgb, n.k_rgb.r, n.k_rgb.g, n.k_rgb.b, 2e-4f);
  // the conversion is linear and maps a constant to itself
  const Scene c = one("Material \"conductor\" \"spectrum eta\" [ 300 1.7 900 1.7 ] \"spectrum k\" [ 400 3 700 3 ]");
  expect_rgb(mat(c, 0).eta_rgb, 1.7f, 1.7f, 1.7f, 1e-5f);
  expect_rgb(mat(c, 0).k_rgb, 3, 3, 3, 1e-5f);
}

// --- dielectrics -------------------------------------------------------------------------

TEST(PbrtMaterials, Dielectric) {
  const Scene s = world("Material \"dielectric\"\n" + tri + "Material \"dielectric\" \"float eta\" 1.33 \"float roughness\" 0.01\n" + tri +
                        "Material \"dielectric\" \"spectrum eta\" [ 400 1.4 800 1.4 ]\n" + tri);
  EXPECT_EQ(mat(s, 0).kind, MaterialKind::dielectric);
  EXPECT_FLOAT_EQ(mat(s, 0).eta, 1.5f);
  EXPECT_EQ(mat(s, 0).alpha_u.value, 0);
  EXPECT_FLOAT_EQ(mat(s, 1).eta, 1.33f);
  EXPECT_NEAR(mat(s, 1).alpha_u.value, 0.1f, 1e-6);
  EXPECT_NEAR(mat(s, 1).alpha_v.value, 0.1f, 1e-6);
  EXPECT_FLOAT_EQ(mat(s, 2).eta, 1.4f);
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];  // a constant spectrum is not dispersive
}

TEST(PbrtMaterials, NamedGlassAt550nm) {
  const Scene s = one("Material \"dielectric\" \"spectrum eta\" \"glass-BK7\"");
  // pbrt-v4's GlassBK7_eta: 542 nm -> 1.5189334783109, 564 nm -> 1.5178426478869
  const double want = 1.5189334783109 + (1.5178426478869 - 1.5189334783109) * (550.0 - 542) / (564 - 542);
  EXPECT_NEAR(mat(s, 0).eta, want, 1e-5);
  EXPECT_TRUE(has_warning(s, "dispersion"));
  const Scene f = one("Material \"thindielectric\" \"spectrum eta\" \"glass-F11\"");
  EXPECT_EQ(mat(f, 0).kind, MaterialKind::thin_dielectric);
  EXPECT_GT(mat(f, 0).eta, 1.78f);
  EXPECT_LT(mat(f, 0).eta, 1.80f);
}

TEST(PbrtMaterials, ThinDielectric) {
  const Scene s = world("Material \"thindielectric\"\n" + tri + "Material \"thindielectric\" \"float eta\" 1.2\n" + tri);
  EXPECT_EQ(mat(s, 0).kind, MaterialKind::thin_dielectric);
  EXPECT_FLOAT_EQ(mat(s, 0).eta, 1.5f);
  EXPECT_FLOAT_EQ(mat(s, 1).eta, 1.2f);
}

// --- diffuse transmission and coated materials ---------------------------------------------

TEST(PbrtMaterials, DiffuseTransmission) {
  write_tga(tmp_dir() / "dt.tga", 1, 1, {255, 255, 255});
  const Scene s = world(
      "Texture \"w\" \"spectrum\" \"imagemap\" \"string filename\" \"dt.tga\"\n"
      "Material \"diffusetransmission\"\n" + tri +
      "Material \"diffusetransmission\" \"rgb reflectance\" [0.1 0.2 0.3] \"rgb transmittance\" [0.3 0.2 0.1] \"float scale\" 2\n" + tri +
      "Material \"diffusetransmission\" \"texture transmittance\" \"w\" \"float scale\" 0.5\n" + tri);
  const Material& d = mat(s, 0);
  EXPECT_EQ(d.kind, MaterialKind::diffuse_transmission);
  expect_rgb(d.reflectance, 0.25f, 0.25f, 0.25f);
  expect_rgb(d.transmittance, 0.25f, 0.25f, 0.25f);
  expect_rgb(mat(s, 1).reflectance, 0.2f, 0.4f, 0.6f);
  expect_rgb(mat(s, 1).transmittance, 0.6f, 0.4f, 0.2f);
  const Material& t = mat(s, 2);
  ASSERT_GE(t.transmittance_texture, 0);
  EXPECT_NEAR(s.textures[size_t(t.transmittance_texture)].rgb[0], 0.5f, 1e-6);  // the scale applies to textures too
  expect_rgb(t.reflectance, 0.125f, 0.125f, 0.125f);
}

TEST(PbrtMaterials, CoatedDiffuse) {
  const Scene s = world("Material \"coateddiffuse\"\n" + tri +
                        "Material \"coateddiffuse\" \"rgb reflectance\" [0.7 0.6 0.5] \"float roughness\" 0.25 \"float thickness\" 0.1 "
                        "\"float eta\" 1.33 \"rgb albedo\" [0.1 0.2 0.3] \"float g\" 0.4 \"integer maxdepth\" 3 \"integer nsamples\" 4 "
                        "\"bool remaproughness\" false\n" + tri);
  const Material& d = mat(s, 0);
  EXPECT_EQ(d.kind, MaterialKind::coated_diffuse);
  expect_rgb(d.reflectance, 0.5f, 0.5f, 0.5f);
  EXPECT_EQ(d.alpha_u.value, 0);
  EXPECT_FLOAT_EQ(d.thickness, 0.01f);
  EXPECT_FLOAT_EQ(d.eta, 1.5f);
  expect_rgb(d.albedo, 0, 0, 0);
  EXPECT_EQ(d.g, 0);
  EXPECT_EQ(d.max_depth, 10);
  EXPECT_EQ(d.nsamples, 1);
  const Material& c = mat(s, 1);
  expect_rgb(c.reflectance, 0.7f, 0.6f, 0.5f);
  EXPECT_FALSE(c.remap_roughness);
  EXPECT_FLOAT_EQ(c.alpha_u.value, 0.25f);
  EXPECT_FLOAT_EQ(c.alpha_v.value, 0.25f);
  EXPECT_FLOAT_EQ(c.thickness, 0.1f);
  EXPECT_FLOAT_EQ(c.eta, 1.33f);
  expect_rgb(c.albedo, 0.1f, 0.2f, 0.3f);
  EXPECT_FLOAT_EQ(c.g, 0.4f);
  EXPECT_EQ(c.max_depth, 3);
  EXPECT_EQ(c.nsamples, 4);
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];
}

TEST(PbrtMaterials, CoatedConductor) {
  const Scene s = world("Material \"coatedconductor\"\n" + tri +
                        "Material \"coatedconductor\" \"float interface.roughness\" 0.09 \"float interface.eta\" 1.7 "
                        "\"spectrum conductor.eta\" \"metal-Au-eta\" \"spectrum conductor.k\" \"metal-Au-k\" "
                        "\"float conductor.uroughness\" 0.16 \"float conductor.vroughness\" 0.36 \"float thickness\" 0.02\n" + tri +
                        "Material \"coatedconductor\" \"rgb reflectance\" [0.5 0.5 0.5]\n" + tri);
  const Scene cu = one("Material \"conductor\"");
  const Scene au = one("Material \"conductor\" \"spectrum eta\" \"metal-Au-eta\" \"spectrum k\" \"metal-Au-k\"");
  const Material& d = mat(s, 0);
  EXPECT_EQ(d.kind, MaterialKind::coated_conductor);
  EXPECT_FLOAT_EQ(d.eta, 1.5f);
  expect_rgb(d.eta_rgb, mat(cu, 0).eta_rgb.r, mat(cu, 0).eta_rgb.g, mat(cu, 0).eta_rgb.b, 0);  // copper
  EXPECT_EQ(d.alpha_u.value, 0);
  EXPECT_EQ(d.base_alpha_u.value, 0);
  EXPECT_FLOAT_EQ(d.thickness, 0.01f);
  const Material& c = mat(s, 1);
  EXPECT_NEAR(c.alpha_u.value, 0.3f, 1e-6);
  EXPECT_NEAR(c.alpha_v.value, 0.3f, 1e-6);
  EXPECT_FLOAT_EQ(c.eta, 1.7f);
  expect_rgb(c.eta_rgb, mat(au, 0).eta_rgb.r, mat(au, 0).eta_rgb.g, mat(au, 0).eta_rgb.b, 0);
  expect_rgb(c.k_rgb, mat(au, 0).k_rgb.r, mat(au, 0).k_rgb.g, mat(au, 0).k_rgb.b, 0);
  EXPECT_NEAR(c.base_alpha_u.value, 0.4f, 1e-6);
  EXPECT_NEAR(c.base_alpha_v.value, 0.6f, 1e-6);
  EXPECT_FLOAT_EQ(c.thickness, 0.02f);
  expect_rgb(mat(s, 2).eta_rgb, 1, 1, 1);
  EXPECT_NEAR(mat(s, 2).k_rgb.g, 2.0f, 1e-5);
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];
}

// --- mix ---------------------------------------------------------------------------------

TEST(PbrtMaterials, MixPointsAtItsMaterials) {
  const Scene s = world(
      "MakeNamedMaterial \"a\" \"string type\" \"diffuse\" \"rgb reflectance\" [1 0 0]\n"
      "MakeNamedMaterial \"b\" \"string type\" \"conductor\"\n"
      "Material \"mix\" \"string materials\" [\"a\" \"b\"] \"float amount\" 0.3\n" + tri +
      "Material \"mix\" \"string materials\" [\"a\" \"b\"]\n" + tri);
  const Material& m = mat(s, 0);
  ASSERT_GE(m.mix[0], 0);
  EXPECT_FLOAT_EQ(s.materials[size_t(m.mix[0])].reflectance.r, 1);
  EXPECT_EQ(s.materials[size_t(m.mix[1])].kind, MaterialKind::conductor);
  EXPECT_FLOAT_EQ(m.mix_amount.value, 0.3f);
  EXPECT_EQ(m.mix_amount.texture, -1);
  EXPECT_FLOAT_EQ(mat(s, 1).mix_amount.value, 0.5f);
  EXPECT_TRUE(m.approximated_from.empty());
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];
}

TEST(PbrtMaterials, NestedMixesBecomeMixesOfLeaves) {
  const Scene s = world(
      "MakeNamedMaterial \"a\" \"string type\" \"diffuse\"\n"
      "MakeNamedMaterial \"b\" \"string type\" \"conductor\"\n"
      "MakeNamedMaterial \"c\" \"string type\" \"dielectric\"\n"
      "MakeNamedMaterial \"ab\" \"string type\" \"mix\" \"string materials\" [\"a\" \"b\"] \"float amount\" 0.5\n"
      "Material \"mix\" \"string materials\" [\"ab\" \"a\"] \"float amount\" 0.5\n" + tri +
      "Material \"mix\" \"string materials\" [\"ab\" \"c\"] \"float amount\" 0.1\n" + tri);
  // ab with 1/2 (a 1/4, b 1/4) and a with 1/2: a 3/4, b 1/4, exactly a mix of a and b
  const Material& m = mat(s, 0);
  const int a = s.materials[size_t(m.mix[0])].kind == MaterialKind::diffuse ? m.mix[0] : m.mix[1];
  const int b = m.mix[0] == a ? m.mix[1] : m.mix[0];
  EXPECT_EQ(s.materials[size_t(a)].kind, MaterialKind::diffuse);
  EXPECT_EQ(s.materials[size_t(b)].kind, MaterialKind::conductor);
  EXPECT_NEAR(m.mix[1] == b ? m.mix_amount.value : 1 - m.mix_amount.value, 0.25f, 1e-6);
  EXPECT_TRUE(m.approximated_from.empty());
  for (int e : m.mix) EXPECT_LT(s.materials[size_t(e)].mix[0], 0);
  // three leaves (a .45, b .45, c .1): approximated, with a warning
  const Material& t = mat(s, 1);
  EXPECT_EQ(t.approximated_from, "mix");
  for (int e : t.mix) EXPECT_LT(s.materials[size_t(e)].mix[0], 0);
  EXPECT_TRUE(has_warning(s, "mix"));
}

TEST(PbrtMaterials, MixErrors) {
  std::string b = "Material \"mix\" \"string materials\" [\"a\" \"nope\"]\n";
  expect_error("MakeNamedMaterial \"a\" \"string type\" \"diffuse\"\n" + b, "\"string materials\"", "nope");
  b = "MakeNamedMaterial \"i\" \"string type\" \"interface\"\nMakeNamedMaterial \"a\" \"string type\" \"diffuse\"\n"
      "Material \"mix\" \"string materials\" [\"a\" \"i\"]\n";
  expect_error(b, "\"string materials\"", "interface");
  b = "Material \"mix\"\n";
  expect_error(b, "Material", "materials");
}

// --- float textures ------------------------------------------------------------------------

TEST(PbrtMaterials, FloatTexturesForRoughnessAmountAndDisplacement) {
  write_tga(tmp_dir() / "rough.tga", 2, 1, {51, 0, 0, 255, 255, 255});
  const std::string body =
      "Texture \"r\" \"float\" \"imagemap\" \"string filename\" \"rough.tga\"\n"
      "Texture \"c\" \"float\" \"constant\" \"float value\" 0.09\n"
      "Texture \"s\" \"float\" \"scale\" \"texture tex\" \"r\" \"float scale\" 2\n"
      "Texture \"m\" \"float\" \"mix\" \"texture tex1\" \"r\" \"texture tex2\" \"s\" \"float amount\" 0.5\n"
      "Material \"conductor\" \"texture roughness\" \"r\" \"texture displacement\" \"s\"\n" + tri +
      "Material \"dielectric\" \"texture roughness\" \"c\" \"float displacement\" 0.5\n" + tri +
      "MakeNamedMaterial \"a\" \"string type\" \"diffuse\"\nMakeNamedMaterial \"b\" \"string type\" \"conductor\"\n"
      "Material \"mix\" \"string materials\" [\"a\" \"b\"] \"texture amount\" \"m\"\n" + tri;
  const Scene s = world(body);
  const Material& c = mat(s, 0);
  ASSERT_GE(c.alpha_u.texture, 0);
  EXPECT_EQ(c.alpha_u.texture, c.alpha_v.texture);
  EXPECT_TRUE(c.remap_roughness);  // the renderer remaps textured roughness at the hit
  const FloatTexture& r = s.float_textures[size_t(c.alpha_u.texture)];
  ASSERT_EQ(r.width, 2);
  ASSERT_EQ(r.height, 1);
  // the average of R, G and B (pbrt-v4's bilinear lookup, the default filter) of a TGA,
  // sRGB-decoded as pbrt-v4's stb_image path decodes it: (51, 0, 0) and (255, 255, 255)
  const float srgb51 = std::pow((0.2f + 0.055f) / 1.055f, 2.4f) / 3;
  EXPECT_NEAR(r.value[0], srgb51, 1e-6);
  EXPECT_NEAR(r.value[1], 1.0f, 1e-6);
  ASSERT_GE(c.displacement, 0);
  const FloatTexture& d = s.float_textures[size_t(c.displacement)];
  EXPECT_NEAR(d.value[0], 2 * srgb51, 1e-6);
  EXPECT_NEAR(d.value[1], 2.0f, 1e-6);
  // a constant texture folds into the value, remapped
  const Material& g = mat(s, 1);
  EXPECT_EQ(g.alpha_u.texture, -1);
  EXPECT_NEAR(g.alpha_u.value, 0.3f, 1e-6);
  ASSERT_GE(g.displacement, 0);
  EXPECT_EQ(s.float_textures[size_t(g.displacement)].width, 1);
  EXPECT_FLOAT_EQ(s.float_textures[size_t(g.displacement)].value[0], 0.5f);
  // mix amount: the mix of r and 2r at 0.5 = 1.5 r, baked
  const Material& m = mat(s, 2);
  ASSERT_GE(m.mix_amount.texture, 0);
  const FloatTexture& a = s.float_textures[size_t(m.mix_amount.texture)];
  EXPECT_NEAR(a.value[0], 1.5f * srgb51, 1e-6);
  EXPECT_NEAR(a.value[1], 1.5f, 1e-6);
  EXPECT_TRUE(s.warnings.empty()) << s.warnings[0];
}

// A float image texture as pbrt-v4 reads it through its MIPMap: "filter" bilinear (the
// default) and trilinear take the average of R, G and B, point and EWA the first channel;
// EWA is read as trilinear and an unknown filter as bilinear, each with a warning. The
// filter is kept for the bump map's lookups.
TEST(PbrtMaterials, FloatImageFiltersAndChannelsAsPbrtV4) {
  write_png8((tmp_dir() / "rgb.png").string(), 1, 1, std::vector<unsigned char>{51, 102, 255});
  const auto srgb = [](float v) { return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f); };
  const float r = srgb(0.2f), g = srgb(0.4f), b = 1.f;
  struct Case {
    std::string filter;
    TexFilter want;
    float value;
    const char* warning;
  };
  const Case cases[] = {{"", TexFilter::bilinear, (r + g + b) / 3, nullptr},
                        {"bilinear", TexFilter::bilinear, (r + g + b) / 3, nullptr},
                        {"trilinear", TexFilter::trilinear, (r + g + b) / 3, nullptr},
                        {"point", TexFilter::point, r, nullptr},
                        {"ewa", TexFilter::trilinear, r, "approximated by trilinear"},
                        {"nearest", TexFilter::bilinear, (r + g + b) / 3, "is unknown"}};
  for (const Case& c : cases) {
    const std::string f = c.filter.empty() ? "" : " \"string filter\" \"" + c.filter + "\"";
    const Scene s = world("Texture \"d\" \"float\" \"imagemap\" \"string filename\" \"rgb.png\"" + f + "\n" +
                          "Material \"diffuse\" \"texture displacement\" \"d\"\n" + tri);
    const Material& m = mat(s, 0);
    ASSERT_GE(m.displacement, 0) << c.filter;
    const FloatTexture& t = s.float_textures[size_t(m.displacement)];
    EXPECT_EQ(t.filter, c.want) << c.filter;
    ASSERT_EQ(t.value.size(), 1u);
    EXPECT_NEAR(t.value[0], c.value, 1e-6) << c.filter;
    if (c.warning) EXPECT_TRUE(has_warning(s, c.warning)) << c.filter;
    else EXPECT_TRUE(s.warnings.empty()) << c.filter << ": " << s.warnings[0];
  }
}

// The encoding of 8-bit image textures, as pbrt-v4 decodes them: a PNG by the texture's
// "encoding" (default sRGB), a TGA (like every format pbrt-v4 reads through stb_image) as
// sRGB whatever the texture says, which is reported; float and spectrum textures alike.
// (pbrt-v4's textures default to "linear" for files that are not PNG, but its Image::Read
// never passes that encoding to those formats: the bathroom's bump maps are TGAs.)
TEST(PbrtMaterials, ImageTextureEncodingsAsPbrtV4DecodesThem) {
  const std::vector<uint8_t> px = {51, 51, 51, 204, 204, 204};
  write_tga(tmp_dir() / "enc.tga", 2, 1, px);
  write_png8((tmp_dir() / "enc.png").string(), 2, 1, std::vector<unsigned char>(px.begin(), px.end()));
  const auto srgb = [](float v) { return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f); };
  const float lo = 51 / 255.f, hi = 204 / 255.f;
  struct Case {
    std::string file, encoding;
    float v0, v1;
    bool warns;
  };
  const Case cases[] = {
      {"enc.tga", "", srgb(lo), srgb(hi), false},         {"enc.tga", "linear", srgb(lo), srgb(hi), true},
      {"enc.tga", "gamma 2.2", srgb(lo), srgb(hi), true}, {"enc.png", "", srgb(lo), srgb(hi), false},
      {"enc.png", "linear", lo, hi, false},               {"enc.png", "gamma 2.2", std::pow(lo, 2.2f), std::pow(hi, 2.2f), false},
  };
  for (const Case& c : cases) {
    const std::string enc = c.encoding.empty() ? "" : " \"string encoding\" \"" + c.encoding + "\"";
    const Scene s = world("Texture \"f\" \"float\" \"imagemap\" \"string filename\" \"" + c.file + "\"" + enc + "\n" +
                          "Texture \"k\" \"spectrum\" \"imagemap\" \"string filename\" \"" + c.file + "\"" + enc + "\n" +
                          "Material \"diffuse\" \"texture reflectance\" \"k\" \"texture displacement\" \"f\"\n" + tri);
    const Material& m = mat(s, 0);
    ASSERT_GE(m.displacement, 0) << c.file << c.encoding;
    const FloatTexture& f = s.float_textures[size_t(m.displacement)];
    ASSERT_EQ(f.value.size(), 2u);
    EXPECT_NEAR(f.value[0], c.v0, 1e-6) << c.file << " " << c.encoding;
    EXPECT_NEAR(f.value[1], c.v1, 1e-6) << c.file << " " << c.encoding;
    ASSERT_GE(m.texture, 0) << c.file << c.encoding;
    const Texture& k = s.textures[size_t(m.texture)];
    ASSERT_EQ(k.rgb.size(), 6u);
    EXPECT_NEAR(k.rgb[0], c.v0, 1e-6) << c.file << " " << c.encoding;
    EXPECT_NEAR(k.rgb[5], c.v1, 1e-6) << c.file << " " << c.encoding;
    EXPECT_EQ(has_warning(s, "encoding"), c.warns) << c.file << " " << c.encoding;
  }
}

TEST(PbrtMaterials, FloatTextureCombinationsThatCannotBeBaked) {
  write_tga(tmp_dir() / "one.tga", 1, 1, {255, 0, 0});
  write_tga(tmp_dir() / "two.tga", 2, 1, {0, 0, 0, 0, 0, 0});
  const Scene s = world(
      "Texture \"x\" \"float\" \"imagemap\" \"string filename\" \"one.tga\"\n"
      "Texture \"y\" \"float\" \"imagemap\" \"string filename\" \"two.tga\"\n"
      "Texture \"m\" \"float\" \"mix\" \"texture tex1\" \"x\" \"texture tex2\" \"y\" \"float amount\" 0.25\n"
      "Texture \"n\" \"float\" \"fbm\"\n"
      "Material \"conductor\" \"texture roughness\" \"m\" \"texture displacement\" \"n\"\n" + tri);
  const Material& c = mat(s, 0);
  EXPECT_EQ(c.alpha_u.texture, -1);
  EXPECT_NEAR(c.alpha_u.value, std::sqrt(0.75f / 3), 1e-6);  // averages: 0.75 * (1 + 0 + 0) / 3 + 0.25 * 0
  EXPECT_TRUE(has_warning(s, "m.pbrt:4"));  // the mix, named by file and line
  EXPECT_TRUE(has_warning(s, "\"fbm\""));
}

// --- errors and warnings -------------------------------------------------------------------

TEST(PbrtMaterials, BadInputIsAnErrorNamingFileAndLine) {
  std::string b = "Material \"conductor\" \"spectrum eta\" \"metal-Xx-eta\"\n";
  expect_error(b, "\"spectrum eta\"", "metal-Xx-eta");
  b = "Material \"dielectric\" \"float eta\" -1.5\n";
  expect_error(b, "\"float eta\"", "negative");
  b = "Material \"dielectric\" \"float eta\" nan\n";
  EXPECT_NE(error_of(b).find("m.pbrt:2:"), std::string::npos) << error_of(b);
  b = "Material \"conductor\" \"float roughness\" -0.1\n";
  expect_error(b, "\"float roughness\"", "negative");
  b = "Texture \"t\" \"spectrum\" \"constant\" \"rgb value\" [1 1 1]\nMaterial \"conductor\" \"texture roughness\" \"t\"\n";
  expect_error(b, "\"texture roughness\"", "spectrum texture");
  b = "Texture \"f\" \"float\" \"constant\" \"float value\" 1\nMaterial \"diffuse\" \"texture reflectance\" \"f\"\n";
  expect_error(b, "\"texture reflectance\"", "float texture");
  b = "Material \"conductor\" \"texture roughness\" \"nope\"\n";
  expect_error(b, "\"texture roughness\"", "nope");
  b = "Material \"conductor\" \"rgb reflectance\" [0.5 0.5 0.5] \"rgb eta\" [1 1 1]\n";
  expect_error(b, "\"rgb reflectance\"", "reflectance");
  b = "Material \"conductor\" \"spectrum k\" [ 500 1 400 2 ]\n";
  expect_error(b, "\"spectrum k\"", "wavelengths");
  b = "Material \"conductor\" \"float eta\" 1.5\n";
  expect_error(b, "\"float eta\"", "rgb/spectrum/texture");
  b = "Material \"coateddiffuse\" \"integer nsamples\" 0\n";
  expect_error(b, "\"integer nsamples\"", "nsamples");
}

// One policy for missing images, float and colour textures alike: the image's mean 0.5 (as
// the imagemap's scale and invert turn it) with a warning naming file and line; with
// --strict (LoadOptions::strict), pbrt-v4's error naming them.
TEST(PbrtMaterials, MissingImagesFallBackToAConstantUnlessStrict) {
  const std::string rough = "Texture \"f\" \"float\" \"imagemap\" \"string filename\" \"missing.tga\" \"float scale\" 0.5\n"
                            "Material \"conductor\" \"texture roughness\" \"f\"\n" + tri;
  const Scene s = world(rough);
  const Material& c = mat(s, 0);
  EXPECT_EQ(c.alpha_u.texture, -1);
  EXPECT_NEAR(c.alpha_u.value, 0.5f, 1e-6);  // roughness 0.5 * 0.5, remapped: sqrt(0.25)
  EXPECT_TRUE(has_warning(s, "m.pbrt:2"));
  EXPECT_TRUE(has_warning(s, "missing.tga"));
  const std::string colour = "Texture \"c\" \"spectrum\" \"imagemap\" \"string filename\" \"gone.png\"\n"
                             "Material \"diffuse\" \"texture reflectance\" \"c\"\n" + tri;
  const Scene s2 = world(colour);
  EXPECT_TRUE(has_warning(s2, "gone.png"));
  EXPECT_TRUE(has_warning(s2, "m.pbrt:2"));
  for (const std::string& body : {rough, colour}) {
    try {
      load_pbrt_string("WorldBegin\n" + body, "m.pbrt", tmp_dir().string(), LoadOptions{true});
      ADD_FAILURE() << "no error under strict";
    } catch (const SceneError& e) {
      EXPECT_EQ(std::string(e.what()).rfind("m.pbrt:2", 0), 0u) << e.what();
      EXPECT_NE(std::string(e.what()).find(body == rough ? "missing.tga" : "gone.png"), std::string::npos) << e.what();
    }
  }
}

// A shape's "alpha": a float on the shape (meshes and spheres), a float texture on meshes
// (looked up per hit), its mean on spheres (with a warning); no "not supported" warning;
// bad values name file and line.
TEST(PbrtMaterials, ShapeAlphaFloatAndTexture) {
  write_tga(tmp_dir() / "mask.tga", 2, 1, {0, 0, 0, 255, 255, 255});
  const Scene s = world(
      "Texture \"m\" \"float\" \"imagemap\" \"string filename\" \"mask.tga\"\n"
      "Texture \"k\" \"float\" \"constant\" \"float value\" 0.25\n"
      "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2] \"texture alpha\" \"m\"\n"
      "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2] \"float alpha\" 0.5\n"
      "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0] \"integer indices\" [0 1 2] \"texture alpha\" \"k\"\n"
      "Shape \"sphere\" \"float alpha\" 0.75\n"
      "Translate 5 0 0 Shape \"sphere\" \"texture alpha\" \"m\"\n"
      "Shape \"disk\"\n");
  ASSERT_EQ(s.meshes.size(), 4u);
  ASSERT_GE(s.meshes[0].alpha.texture, 0);
  const FloatTexture& t = s.float_textures[size_t(s.meshes[0].alpha.texture)];
  ASSERT_EQ(t.width, 2);
  EXPECT_NEAR(t.value[0], 0.f, 1e-6);
  EXPECT_NEAR(t.value[1], 1.f, 1e-6);
  EXPECT_TRUE(s.meshes[0].has_alpha());
  EXPECT_EQ(s.meshes[1].alpha.texture, -1);
  EXPECT_EQ(s.meshes[1].alpha.value, 0.5f);
  EXPECT_EQ(s.meshes[2].alpha.texture, -1);  // a constant texture is a constant
  EXPECT_EQ(s.meshes[2].alpha.value, 0.25f);
  EXPECT_FALSE(s.meshes[3].has_alpha());
  ASSERT_EQ(s.spheres.size(), 2u);
  EXPECT_EQ(s.spheres[0].alpha, 0.75f);
  EXPECT_NEAR(s.spheres[1].alpha, 0.5f, 1e-6);  // the mask's mean
  EXPECT_TRUE(has_warning(s, "m.pbrt:8: an alpha texture on a sphere"));
  for (const std::string& w : s.warnings) EXPECT_EQ(w.find("\"alpha\" is not supported"), std::string::npos) << w;
  const std::string inf = "Shape \"sphere\" \"float alpha\" 1e999\n";
  EXPECT_EQ(error_of(inf).rfind("m.pbrt:2", 0), 0u) << error_of(inf);
  const std::string two = "Shape \"sphere\" \"float alpha\" [0.5 0.5]\n";
  EXPECT_NE(error_of(two).find("m.pbrt:2"), std::string::npos) << error_of(two);
  const std::string unknown = "Shape \"sphere\" \"texture alpha\" \"nope\"\n";
  EXPECT_NE(error_of(unknown).find("unknown float texture"), std::string::npos) << error_of(unknown);
}

TEST(PbrtMaterials, WarningsSayWhatIsApproximated) {
  const Scene s = world(
      "Material \"conductor\" \"float roughnes\" 0.1\n" + tri + "Material \"measured\"\n" + tri +
      "Material \"diffuse\" \"string normalmap\" \"n.png\"\n" + tri + "Material \"interface\"\n" + tri);
  EXPECT_TRUE(has_warning(s, "roughnes\" of Material \"conductor\""));
  EXPECT_TRUE(has_warning(s, "m.pbrt:4: material \"measured\" approximated as diffuse"));
  EXPECT_EQ(mat(s, 1).approximated_from, "measured");
  EXPECT_TRUE(has_warning(s, "normalmap"));
  // a media boundary: its shapes are left out, rays pass through them (tests/test_media.cpp)
  ASSERT_EQ(s.meshes.size(), 3u);
  ASSERT_EQ(s.materials.size(), 4u);
  EXPECT_TRUE(s.materials[3].interface);
  EXPECT_TRUE(s.materials[3].approximated_from.empty());
}
