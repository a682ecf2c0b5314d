// The pbrt-v4 reader's textures: Texture definitions -- spectrum (imagemap, constant, scale,
// mix, checkerboard) as TexDefs and float (imagemap, constant, scale, mix, checkerboard) as
// FloatTexDefs -- recorded while parsing, the image files they read (decoded in parallel at
// the end), and their resolution to scene textures, float textures or constants
// (bake_materials, in loader_materials.cpp, sets them into the materials that use them).
#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "image.h"
#include "lexer.h"
#include "loader_state.h"
#include "params.h"
#include "util.h"

namespace tuile::pbrt {

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
    float_texture(lx, t, name, cls, ps);
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
    const std::string enc = image_encoding(ps, path, where);
    d.kind = TexDef::image;
    d.scale = ps.one_float("scale", 1);
    d.job = image_job(path, enc, where);
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
  mapping_warnings(ps, where);
  warn_unused(ps, "Texture \"" + cls + "\"", lx, t);
  texdefs_.push_back(d);
  textures_[name] = int(texdefs_.size() - 1);
}

void Loader::mapping_warnings(Params& ps, const std::string& where) {
  for (Param& p : ps.items)
    if (p.name == "mapping" || p.name == "uscale" || p.name == "vscale" || p.name == "udelta" || p.name == "vdelta") {
      if (!p.used && !(p.strs.size() == 1 && p.strs[0] == "uv") &&
          !(p.nums.size() == 1 && p.nums[0] == ((p.name == "uscale" || p.name == "vscale") ? 1 : 0)))
        warn("mapping", where + ": texture mappings other than plain uv are not supported and were ignored");
      p.used = true;
    }
}

// The encoding an image texture's 8- and 16-bit values are decoded with, as pbrt-v4 decodes
// them: a PNG by the texture's "encoding" (default sRGB); every other such format (TGA,
// JPEG, BMP, ...), which pbrt-v4's Image::Read hands to stb_image, as sRGB whatever the
// texture says: pbrt-v4's image textures default to "linear" for files that are not PNG,
// but that default never reaches these formats, so a float texture of a TGA (a bump map, a
// roughness or alpha map) is sRGB-decoded. An encoding other than sRGB on such a file is
// reported (pbrt-v4 ignores it silently). Float formats (EXR, HDR, PFM) are linear values;
// their encoding is not read.
std::string Loader::image_encoding(Params& ps, const std::string& path, const std::string& where) {
  const auto ext_is = [&](const char* e) { return ends_with_ci(path, e); };
  if (ext_is(".exr") || ext_is(".hdr") || ext_is(".pfm")) {
    ps.get("encoding", "string");
    return "linear";
  }
  if (ext_is(".png")) return ps.one_string("encoding", "sRGB");
  const std::string enc = ps.one_string("encoding", "sRGB");
  if (enc != "sRGB")
    warn("encoding:" + path, where + ": imagemap \"" + path + "\": \"encoding\" \"" + enc +
                                 "\" ignored: pbrt-v4 decodes this format as sRGB whatever the file says, and so does tuile");
  return "sRGB";
}

int Loader::image_job(const std::string& path, const std::string& encoding, const std::string& where) {
  auto key = std::make_pair(path, encoding);
  auto it = image_by_path_.find(key);
  if (it == image_by_path_.end()) {
    ImageJob j;
    j.path = path;
    j.encoding = encoding;
    j.where = where;
    scene.inputs.push_back(path);
    images_.push_back(std::move(j));
    it = image_by_path_.emplace(key, int(images_.size() - 1)).first;
  }
  return it->second;
}

// A float operand of a float texture: "float NAME" (or the default) or "texture NAME".
int Loader::float_operand(Params& ps, const std::string& name, float def) {
  const Param* p = ps.get(name, "float|texture");
  if (p && p->type == "texture") return float_texture_ref(*p);
  FloatTexDef c;
  c.value = def;
  if (p) {
    if (p->nums.size() != 1) p->fail("parameter \"float " + name + "\" has " + std::to_string(p->nums.size()) + " values", "1 value");
    c.value = float(p->nums[0]);
  }
  float_defs_.push_back(c);
  return int(float_defs_.size() - 1);
}

// Texture "name" "float" CLASS: constant, imagemap (its first channel, as pbrt-v4's float
// image lookup), scale, mix and 2D checkerboard are baked at the end; bilerp and the
// procedural classes are approximated by a constant.
void Loader::float_texture(Lexer& lx, const Token& t, const std::string& name, const std::string& cls, Params& ps) {
  const std::string where = loc_str(lx, t);
  FloatTexDef d;
  d.name = name;
  d.where = where;
  d.file = lx.file();
  d.line = t.line;
  d.col = t.col;
  if (cls == "constant") {
    d.value = ps.one_float("value", 1);
  } else if (cls == "imagemap") {
    const Param* fp = ps.get("filename", "string");
    if (!fp || fp->strs.size() != 1) lx.fail(t, "imagemap texture \"" + name + "\" without a filename", "a \"string filename\" parameter");
    const std::string path = resolve_path(lx.dir(), fp->strs[0]);
    const std::string enc = image_encoding(ps, path, where);
    d.kind = FloatTexDef::image;
    d.scale = ps.one_float("scale", 1);
    d.invert = ps.one_bool("invert", false);
    d.job = image_job(path, enc, where);
    const std::string wrap = ps.one_string("wrap", "repeat");
    if (wrap != "repeat") warn("wrap", where + ": imagemap wrap \"" + wrap + "\" is not supported: textures repeat");
    const std::string filter = ps.one_string("filter", "bilinear");
    if (filter == "point") d.filter = TexFilter::point;
    else if (filter == "bilinear") d.filter = TexFilter::bilinear;
    else if (filter == "trilinear") d.filter = TexFilter::trilinear;
    else if (filter == "ewa" || filter == "EWA") {
      d.filter = TexFilter::trilinear;
      warn("filter:ewa", where + ": imagemap filter \"" + filter + "\" approximated by trilinear");
    } else
      warn("filter:" + filter, where + ": imagemap filter \"" + filter + "\" is unknown (pbrt-v4 reports it too): bilinear used");
    // pbrt-v4 reads a float image through its MIPMap: point and EWA lookups take the
    // first channel, bilinear and trilinear the average of R, G and B
    d.first_channel = filter == "point" || filter == "ewa" || filter == "EWA";
    ps.get("maxanisotropy", "float");
  } else if (cls == "scale") {
    d.kind = FloatTexDef::product;
    d.a = float_operand(ps, "tex", 1);
    d.b = float_operand(ps, "scale", 1);
  } else if (cls == "mix") {
    d.kind = FloatTexDef::mix;
    d.a = float_operand(ps, "tex1", 0);
    d.b = float_operand(ps, "tex2", 1);
    d.amount = float_operand(ps, "amount", 0.5f);
  } else if (cls == "checkerboard") {
    d.kind = FloatTexDef::checker;
    d.a = float_operand(ps, "tex1", 1);
    d.b = float_operand(ps, "tex2", 0);
    d.uscale = ps.one_float("uscale", 1);
    d.vscale = ps.one_float("vscale", 1);
    d.udelta = ps.one_float("udelta", 0);
    d.vdelta = ps.one_float("vdelta", 0);
    if (ps.one_int("dimension", 2) != 2) {
      warn("checker3d", where + ": 3D checkerboard approximated by the average of its two textures");
      d.kind = FloatTexDef::mix;
      FloatTexDef half;
      half.value = 0.5f;
      float_defs_.push_back(half);
      d.amount = int(float_defs_.size() - 1);
    }
  } else if (cls == "bilerp") {
    d.value = (ps.one_float("v00", 0) + ps.one_float("v01", 1) + ps.one_float("v10", 0) + ps.one_float("v11", 1)) / 4;
    warn("floattex:bilerp", where + ": float texture \"bilerp\" approximated by the average of its corners");
  } else {
    ps.mark_all_used();
    d.value = 0.5f;
    warn("floattex:" + cls, where + ": float texture class \"" + cls + "\" is not supported: the constant 0.5 used");
  }
  mapping_warnings(ps, where);
  warn_unused(ps, "Texture \"" + cls + "\"", lx, t);
  float_defs_.push_back(d);
  float_textures_[name] = int(float_defs_.size() - 1);
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

const Texture& Loader::job_texture(ImageJob& j) {
  return j.scene_index >= 0 ? scene.textures[size_t(j.scene_index)] : j.tex;
}

int Loader::add_float_texture(FloatTexture t) {
  scene.float_textures.push_back(std::move(t));
  return int(scene.float_textures.size() - 1);
}

ResolvedFloat Loader::resolve_float(int fd, int depth) {
  auto memo = resolved_float_.find(fd);
  if (memo != resolved_float_.end()) return memo->second;
  const FloatTexDef d = float_defs_[size_t(fd)];
  ResolvedFloat r;
  r.value = d.value;
  auto value_of = [&](const ResolvedFloat& x) { return x.image ? average(scene.float_textures[size_t(x.texture)]) : x.value; };
  // f over operands texel by texel: constants broadcast; images must have one size, else a
  // constant from their averages.
  auto combine = [&](std::vector<ResolvedFloat> ops, auto f) {
    ResolvedFloat out;
    int w = -1, h = -1;
    bool same = true;
    for (const ResolvedFloat& o : ops)
      if (o.image) {
        const FloatTexture& t = scene.float_textures[size_t(o.texture)];
        if (w < 0) w = t.width, h = t.height;
        else if (t.width != w || t.height != h) same = false;
      }
    std::vector<float> v(ops.size());
    if (w < 0 || !same) {
      if (!same)
        warn("floatcombine", d.where + ": float texture \"" + d.name + "\" combines images of different sizes: approximated by a constant");
      for (size_t i = 0; i < ops.size(); ++i) v[i] = value_of(ops[i]);
      out.value = f(v);
      return out;
    }
    FloatTexture t;
    t.name = d.name;
    t.width = w;
    t.height = h;
    for (const ResolvedFloat& o : ops)  // (read as its first image is)
      if (o.image) {
        t.filter = scene.float_textures[size_t(o.texture)].filter;
        break;
      }
    t.value.resize(size_t(w) * size_t(h));
    for (size_t k = 0; k < t.value.size(); ++k) {
      for (size_t i = 0; i < ops.size(); ++i)
        v[i] = ops[i].image ? scene.float_textures[size_t(ops[i].texture)].value[k] : ops[i].value;
      t.value[k] = f(v);
    }
    out.image = true;
    out.texture = add_float_texture(std::move(t));
    return out;
  };
  if (depth <= 64 && d.kind == FloatTexDef::image && !images_[size_t(d.job)].ok) {
    // one policy for missing images: the image's documented mean, 0.5, as pbrt's imagemap
    // turns it (times "scale", then "invert"), with a warning; --strict: pbrt-v4's error
    const ImageJob& j = images_[size_t(d.job)];
    if (strict)
      fail(d.file, d.line, d.col, "cannot read image '" + j.path + "' of float texture \"" + d.name + "\": " + j.reason,
           "an existing, readable image file (--strict)");
    float v = 0.5f * d.scale;
    if (d.invert) v = std::max(0.f, 1 - v);
    r.value = v;
    warn("image:" + j.path, d.where + ": cannot read image '" + j.path + "' of float texture \"" + d.name + "\" (" + j.reason +
                                "): the constant " + std::to_string(v) + " used (--strict: an error)");
  } else if (depth > 64) {
    r.value = 0.5f;
  } else if (d.kind == FloatTexDef::image) {
    ImageJob& j = images_[size_t(d.job)];
    const auto key = std::make_tuple(d.job, d.scale, d.invert, int(d.filter), d.first_channel);
    auto it = float_images_.find(key);
    if (it == float_images_.end()) {
      const Texture& src = job_texture(j);
      FloatTexture t;
      t.name = d.name;
      t.width = src.width;
      t.height = src.height;
      t.filter = d.filter;
      t.value.resize(size_t(src.width) * size_t(src.height));
      for (size_t i = 0; i < t.value.size(); ++i) {
        const float* c = &src.rgb[3 * i];
        const float v = d.scale * (d.first_channel ? c[0] : (c[0] + c[1] + c[2]) / 3);
        t.value[i] = d.invert ? std::max(0.f, 1 - v) : v;
      }
      it = float_images_.emplace(key, add_float_texture(std::move(t))).first;
    }
    r.image = true;
    r.texture = it->second;
  } else if (d.kind == FloatTexDef::product) {
    r = combine({resolve_float(d.a, depth + 1), resolve_float(d.b, depth + 1)}, [](const std::vector<float>& v) { return v[0] * v[1]; });
  } else if (d.kind == FloatTexDef::mix) {
    r = combine({resolve_float(d.a, depth + 1), resolve_float(d.b, depth + 1), resolve_float(d.amount, depth + 1)},
                [](const std::vector<float>& v) { return (1 - v[2]) * v[0] + v[2] * v[1]; });
  } else if (d.kind == FloatTexDef::checker) {
    const ResolvedFloat a = resolve_float(d.a, depth + 1), b = resolve_float(d.b, depth + 1);
    if (a.image || b.image) {
      warn("checkerimage", d.where + ": checkerboard of image textures approximated by their average");
      r.value = (value_of(a) + value_of(b)) / 2;
    } else {
      warn("checkerbake", d.where + ": checkerboard texture baked into an image over uv [0,1]");
      FloatTexture t;
      t.name = d.name;
      const float checks = std::max(std::abs(d.uscale), std::abs(d.vscale));
      t.width = t.height = int(std::clamp(checks * 16.f, 16.f, 1024.f));
      t.value.resize(size_t(t.width) * size_t(t.height));
      for (int y = 0; y < t.height; ++y)
        for (int x = 0; x < t.width; ++x) {
          const float u = (x + 0.5f) / t.width, v = 1 - (y + 0.5f) / t.height;
          const double s = std::floor(double(u) * d.uscale + d.udelta) + std::floor(double(v) * d.vscale + d.vdelta);
          t.value[size_t(y) * size_t(t.width) + size_t(x)] = std::fmod(std::abs(s), 2.0) == 0 ? a.value : b.value;
        }
      r.image = true;
      r.texture = add_float_texture(std::move(t));
    }
  }
  // a product or a scaled image whose values overflow a float: an error at its definition
  if (r.image ? !std::all_of(scene.float_textures[size_t(r.texture)].value.begin(), scene.float_textures[size_t(r.texture)].value.end(),
                             [](float x) { return std::isfinite(x); })
              : !std::isfinite(r.value))
    fail(d.file, d.line, d.col, "float texture \"" + d.name + "\" has values that are not finite (its product or scale overflows a float)",
         "values whose products fit in a float");
  resolved_float_[fd] = r;
  return r;
}

}  // namespace tuile::pbrt
