// The pbrt-v4 reader's materials and textures: the materials of Material and
// MakeNamedMaterial (diffuse; others approximated as diffuse), Texture definitions (imagemap, constant, scale, mix,
// checkerboard) recorded as TexDefs while parsing, and at the end their resolution to
// scene textures or constants, baked into the materials that use them.
#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

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

int Loader::make_material(Lexer& lx, const Token& t, const std::string& type, Params& ps) {
  const std::string where = loc_str(lx, t);
  Material m;
  int tex = -1;
  auto read_reflectance = [&](const char* name) {
    const Param* p = ps.get(name, "rgb|blackbody|spectrum|texture");
    if (!p) return false;
    if (p->type == "texture") {
      tex = reflectance_texture(lx, *p);
    } else if (!ps.spectrum(name, false, m.reflectance)) {
      warn("namedspectrum", where + ": named spectra are not supported; grey 0.5 used");
    }
    return true;
  };
  if (type == "diffuse") {
    read_reflectance("reflectance");
    for (Param& p : ps.items)
      if (p.name == "displacement" || p.name == "normalmap") {
        p.used = true;
        warn("bump", where + ": displacement and normal maps are not supported and were ignored");
      }
    warn_unused(ps, "Material \"diffuse\"", lx, t);
  } else if (type == "mix") {
    const Param* mp = ps.get("materials", "string");
    auto it = mp && mp->strs.size() == 2 ? named_materials_.find(mp->strs[0]) : named_materials_.end();
    ps.mark_all_used();
    warn("material:mix", where + ": material \"mix\" approximated by its first material");
    if (it != named_materials_.end()) {
      m = scene.materials[size_t(it->second)];
      tex = material_tex_[size_t(it->second)];
    }
    if (m.approximated_from.empty()) m.approximated_from = "mix";
  } else {
    const bool found = read_reflectance("reflectance") || (ps.get("Kd", "rgb|spectrum|texture") && read_reflectance("Kd"));
    m.approximated_from = type.empty() ? "none" : type;
    ps.mark_all_used();
    warn("material:" + type, where + ": material \"" + type + "\" approximated as diffuse (" +
                                 (found ? "its reflectance" : "grey 0.5") + ")");
  }
  scene.materials.push_back(m);
  material_tex_.push_back(tex);
  return int(scene.materials.size() - 1);
}

int Loader::tex_operand(Lexer& lx, Params& ps, const std::string& name, Rgb def) {
  const Param* p = ps.get(name, "rgb|blackbody|spectrum|texture|float");
  TexDef d;
  d.value = def;
  if (p) {
    if (p->type == "texture") return reflectance_texture(lx, *p);
    if (p->type == "float") {
      if (p->nums.size() != 1) p->fail("parameter \"float " + name + "\" has " + std::to_string(p->nums.size()) + " values", "1 value");
      const float v = float(p->nums[0]);
      d.value = {v, v, v};
    } else {
      ps.spectrum(name, false, d.value);
    }
  }
  texdefs_.push_back(d);
  return int(texdefs_.size() - 1);
}

void Loader::texture(Lexer& lx, const Token& t) {
  const std::string where = loc_str(lx, t);
  const std::string name = string_arg(lx, "texture name");
  const std::string kind = string_arg(lx, "texture type (\"spectrum\" or \"float\")");
  const std::string cls = string_arg(lx, "texture class");
  Params ps = read_params(lx);
  if (kind == "float") {
    ps.mark_all_used();
    float_textures_[name] = 0;
    warn("floattex", where + ": float textures (bump maps, roughness) are not supported and were ignored");
    return;
  }
  if (kind != "spectrum" && kind != "color") lx.fail(t, "unknown texture type \"" + kind + "\"", "\"spectrum\" or \"float\"");
  TexDef d;
  d.name = name;
  d.where = where;
  if (cls == "imagemap") {
    const Param* fp = ps.get("filename", "string");
    if (!fp || fp->strs.size() != 1) lx.fail(t, "imagemap texture \"" + name + "\" without a filename", "a \"string filename\" parameter");
    const std::string path = resolve_path(lx.dir(), fp->strs[0]);
    const std::string enc = ps.one_string("encoding", "sRGB");
    d.kind = TexDef::image;
    d.scale = ps.one_float("scale", 1);
    auto key = std::make_pair(path, enc);
    auto it = image_by_path_.find(key);
    if (it == image_by_path_.end()) {
      ImageJob j;
      j.path = path;
      j.encoding = enc;
      j.where = where;
      images_.push_back(std::move(j));
      it = image_by_path_.emplace(key, int(images_.size() - 1)).first;
    }
    d.job = it->second;
    if (ps.one_bool("invert", false)) warn("invert", where + ": imagemap \"invert\" is not supported and was ignored");
    const std::string wrap = ps.one_string("wrap", "repeat");
    if (wrap != "repeat") warn("wrap", where + ": imagemap wrap \"" + wrap + "\" is not supported: textures repeat");
    ps.get("filter", "string");
    ps.get("maxanisotropy", "float");
  } else if (cls == "constant") {
    ps.spectrum("value", false, d.value);
  } else if (cls == "scale") {
    const int base = tex_operand(lx, ps, "tex", {1, 1, 1});
    d = texdefs_[size_t(base)];
    d.name = name;
    d.where = where;
    const Param* sp = ps.get("scale", "float|texture");
    if (sp && sp->type == "texture") {
      warn("scaletex", where + ": a texture as the \"scale\" of a scale texture is not supported: 1 used");
    } else if (sp) {
      if (sp->nums.size() != 1) sp->fail("parameter \"float scale\" has " + std::to_string(sp->nums.size()) + " values", "1 value");
      const float s = float(sp->nums[0]);
      d.scale *= s;
      d.value = {d.value.r * s, d.value.g * s, d.value.b * s};
      if (d.kind == TexDef::constant) d.scale = 1;
    }
  } else if (cls == "mix") {
    d.kind = TexDef::mix;
    d.a = tex_operand(lx, ps, "tex1", {0, 0, 0});
    d.b = tex_operand(lx, ps, "tex2", {1, 1, 1});
    const Param* ap = ps.get("amount", "float|texture");
    if (ap && ap->type == "texture") warn("mixtex", where + ": a texture as the mix \"amount\" is not supported: 0.5 used");
    else if (ap) {
      if (ap->nums.size() != 1) ap->fail("parameter \"float amount\" has " + std::to_string(ap->nums.size()) + " values", "1 value");
      d.amount = float(ap->nums[0]);
    }
  } else if (cls == "checkerboard") {
    d.kind = TexDef::checker;
    d.a = tex_operand(lx, ps, "tex1", {1, 1, 1});
    d.b = tex_operand(lx, ps, "tex2", {0, 0, 0});
    d.uscale = ps.one_float("uscale", 1);
    d.vscale = ps.one_float("vscale", 1);
    d.udelta = ps.one_float("udelta", 0);
    d.vdelta = ps.one_float("vdelta", 0);
    if (ps.one_int("dimension", 2) != 2) {
      warn("checker3d", where + ": 3D checkerboard approximated by the average of its two textures");
      d.kind = TexDef::mix;
      d.amount = 0.5f;
    }
  } else {
    ps.mark_all_used();
    warn("texture:" + cls, where + ": texture class \"" + cls + "\" is not supported: grey 0.5 used");
  }
  for (Param& p : ps.items)
    if (p.name == "mapping" || p.name == "uscale" || p.name == "vscale" || p.name == "udelta" || p.name == "vdelta") {
      if (!p.used && !(p.strs.size() == 1 && p.strs[0] == "uv") &&
          !(p.nums.size() == 1 && p.nums[0] == ((p.name == "uscale" || p.name == "vscale") ? 1 : 0)))
        warn("mapping", where + ": texture mappings other than plain uv are not supported and were ignored");
      p.used = true;
    }
  warn_unused(ps, "Texture \"" + cls + "\"", lx, t);
  texdefs_.push_back(d);
  textures_[name] = int(texdefs_.size() - 1);
}

static Rgb average(const Texture& t) {
  double s[3] = {0, 0, 0};
  const size_t n = size_t(t.width) * t.height;
  for (size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) s[c] += t.rgb[3 * i + c];
  return n ? Rgb{float(s[0] / n), float(s[1] / n), float(s[2] / n)} : Rgb{};
}

Resolved Loader::resolve(int td, int depth) {
  auto memo = resolved_.find(td);
  if (memo != resolved_.end()) return memo->second;
  const TexDef d = texdefs_[size_t(td)];
  Resolved r;
  r.value = d.value;
  auto avg = [&](const Resolved& x) { return x.image ? average(scene.textures[size_t(x.texture)]) : x.value; };
  if (depth > 64) {
    r.value = {0.5f, 0.5f, 0.5f};
  } else if (d.kind == TexDef::image) {
    ImageJob& j = images_[size_t(d.job)];
    if (!j.ok) {
      r.value = {0.5f, 0.5f, 0.5f};
    } else {
      if (j.scene_index < 0) {
        j.tex.name = d.name;
        scene.textures.push_back(std::move(j.tex));
        j.scene_index = int(scene.textures.size() - 1);
      }
      r.image = true;
      r.texture = j.scene_index;
      if (d.scale != 1) {
        Texture t = scene.textures[size_t(j.scene_index)];
        t.name = d.name;
        for (float& v : t.rgb) v *= d.scale;
        scene.textures.push_back(std::move(t));
        r.texture = int(scene.textures.size() - 1);
      }
    }
  } else if (d.kind == TexDef::checker) {
    const Resolved a = resolve(d.a, depth + 1), b = resolve(d.b, depth + 1);
    if (a.image || b.image) {
      warn("checkerimage", d.where + ": checkerboard of image textures approximated by their average");
      const Rgb x = avg(a), y = avg(b);
      r.value = {(x.r + y.r) / 2, (x.g + y.g) / 2, (x.b + y.b) / 2};
    } else {
      // Baked over uv in [0,1]^2 (exact when uscale/vscale are integers and the texture repeats).
      warn("checkerbake", d.where + ": checkerboard texture baked into an image over uv [0,1]");
      Texture t;
      t.name = d.name;
      const float checks = std::max(std::abs(d.uscale), std::abs(d.vscale));
      t.width = t.height = int(std::clamp(checks * 16.f, 16.f, 1024.f));
      t.rgb.resize(size_t(3) * t.width * t.height);
      for (int y = 0; y < t.height; ++y)
        for (int x = 0; x < t.width; ++x) {
          const float u = (x + 0.5f) / t.width, v = 1 - (y + 0.5f) / t.height;  // image rows run top-down in v
          const double s = std::floor(double(u) * d.uscale + d.udelta) + std::floor(double(v) * d.vscale + d.vdelta);
          const Rgb c = std::fmod(std::abs(s), 2.0) == 0 ? a.value : b.value;
          float* p = &t.rgb[3 * (size_t(y) * t.width + x)];
          p[0] = c.r, p[1] = c.g, p[2] = c.b;
        }
      scene.textures.push_back(std::move(t));
      r.image = true;
      r.texture = int(scene.textures.size() - 1);
    }
  } else if (d.kind == TexDef::mix) {
    const Resolved a = resolve(d.a, depth + 1), b = resolve(d.b, depth + 1);
    const float w = d.amount;
    auto lerp = [&](Rgb x, Rgb y) { return Rgb{x.r * (1 - w) + y.r * w, x.g * (1 - w) + y.g * w, x.b * (1 - w) + y.b * w}; };
    const Texture* ta = a.image ? &scene.textures[size_t(a.texture)] : nullptr;
    const Texture* tb = b.image ? &scene.textures[size_t(b.texture)] : nullptr;
    if (!a.image && !b.image) {
      r.value = lerp(a.value, b.value);
    } else if (ta && tb && ta->width == tb->width && ta->height == tb->height) {
      Texture t;
      t.name = d.name;
      t.width = ta->width;
      t.height = ta->height;
      t.rgb.resize(ta->rgb.size());
      for (size_t i = 0; i < t.rgb.size(); ++i) t.rgb[i] = ta->rgb[i] * (1 - w) + tb->rgb[i] * w;
      scene.textures.push_back(std::move(t));
      r.image = true;
      r.texture = int(scene.textures.size() - 1);
    } else {
      warn("miximage", d.where + ": mix of textures of different kinds or sizes approximated by a constant");
      r.value = lerp(avg(a), avg(b));
    }
  }
  resolved_[td] = r;
  return r;
}

void Loader::bake_materials() {
  for (size_t i = 0; i < scene.materials.size(); ++i) {
    if (material_tex_[i] < 0) continue;
    const Resolved r = resolve(material_tex_[i]);
    if (r.image) scene.materials[i].texture = r.texture;
    else scene.materials[i].reflectance = r.value;
  }
}

}  // namespace tuile::pbrt
