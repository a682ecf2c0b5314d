// Checkpoint files: fingerprint, save and load (CRC-32 from zlib).
#include "render/checkpoint.h"

#include <zlib.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>

#include "render/filter_table.h"
#include "scene/atomic_file.h"

namespace tuile {

namespace {

constexpr char kMagic[8] = {'T', 'U', 'I', 'L', 'E', 'C', 'K', 'P'};
constexpr uint32_t kVersion = 1;

struct Crc {
  uLong value = crc32(0L, Z_NULL, 0);
  void add(const void* p, size_t n) {
    const auto* b = static_cast<const Bytef*>(p);
    while (n > 0) {  // zlib takes uInt lengths
      const uInt k = static_cast<uInt>(std::min<size_t>(n, 1u << 30));
      value = crc32(value, b, k);
      b += k;
      n -= k;
    }
  }
  template <class T> void add_vector(const std::vector<T>& v) { add(v.data(), v.size() * sizeof(T)); }
};

// Appends raw bytes, keeping the running CRC.
struct Writer {
  std::FILE* f;
  Crc crc;
  void bytes(const void* p, size_t n) {
    if (n && std::fwrite(p, 1, n, f) != n) throw std::runtime_error("write failed (disk full?)");
    crc.add(p, n);
  }
  template <class T> void value(const T& v) { bytes(&v, sizeof(T)); }
  template <class T, class A> void array(const std::vector<T, A>& v) { bytes(v.data(), v.size() * sizeof(T)); }
};

struct Reader {
  const std::string& data;
  const std::string& path;
  size_t at = 0;
  void bytes(void* p, size_t n) {
    if (n > data.size() - at) throw std::runtime_error(path + ": checkpoint cut short");
    std::memcpy(p, data.data() + at, n);
    at += n;
  }
  template <class T> T value() {
    T v;
    bytes(&v, sizeof(T));
    return v;
  }
  template <class T, class A> void array(std::vector<T, A>& v, size_t n) {
    if (n > (data.size() - at) / sizeof(T)) throw std::runtime_error(path + ": checkpoint cut short");
    v.resize(n);
    bytes(v.data(), n * sizeof(T));
  }
};

}  // namespace

std::string checkpoint_path(const std::string& output) { return output + ".checkpoint"; }

std::string render_fingerprint(const Scene& scene, const RenderOptions& options, const PassPlan& plan) {
  Crc c;
  const Camera& cam = scene.camera;
  c.add(&cam.world_from_camera, sizeof(cam.world_from_camera));
  c.add(&cam.fov_deg, sizeof(cam.fov_deg));
  c.add(&cam.screen, sizeof(cam.screen));
  for (const Mesh& m : scene.meshes) {
    c.add_vector(m.positions);
    c.add_vector(m.indices);
    c.add_vector(m.uvs);
    c.add(&m.material, sizeof(m.material));
    c.add(&m.emission, sizeof(m.emission));
    const uint8_t flags[2] = {m.two_sided, m.reverse_orientation};
    c.add(flags, sizeof(flags));
    if (!m.normals.empty()) c.add_vector(m.normals);  // (absent: the fingerprint of earlier releases)
  }
  for (const Instance& in : scene.instances) {  // (none: the fingerprint of earlier releases)
    c.add(&in.object, sizeof(in.object));
    c.add(&in.world_from_object, sizeof(in.world_from_object));
  }
  for (const Sphere& s : scene.spheres) {
    c.add(&s.center, sizeof(s.center));
    c.add(&s.radius, sizeof(s.radius));
    c.add(&s.material, sizeof(s.material));
    c.add(&s.emission, sizeof(s.emission));
    const uint8_t reverse = s.reverse_orientation;
    c.add(&reverse, 1);
  }
  for (const Curves& cv : scene.curves) {
    c.add_vector(cv.points);
    c.add_vector(cv.normals);
    c.add(&cv.type, sizeof(cv.type));
    c.add(&cv.material, sizeof(cv.material));
  }
  for (const Material& m : scene.materials) {
    c.add(&m.reflectance, sizeof(m.reflectance));
    c.add(&m.texture, sizeof(m.texture));
    // the other surfaces' parameters; a plain diffuse material adds nothing more, so that
    // diffuse scenes keep the fingerprint of earlier releases
    if (m.kind != MaterialKind::diffuse || m.mix[0] >= 0 || m.displacement >= 0) {
      const float f[] = {m.transmittance.r, m.transmittance.g, m.transmittance.b, m.eta_rgb.r, m.eta_rgb.g, m.eta_rgb.b,
                         m.k_rgb.r,         m.k_rgb.g,         m.k_rgb.b,         m.eta,       m.alpha_u.value,
                         m.alpha_v.value,   m.base_alpha_u.value, m.base_alpha_v.value, m.thickness, m.albedo.r,
                         m.albedo.g,        m.albedo.b,        m.g,               m.mix_amount.value};
      const int32_t i[] = {static_cast<int32_t>(m.kind), m.transmittance_texture, m.alpha_u.texture, m.alpha_v.texture,
                           m.base_alpha_u.texture, m.base_alpha_v.texture, m.remap_roughness, m.displacement,
                           m.mix[0], m.mix[1], m.mix_amount.texture};
      c.add(f, sizeof(f));
      c.add(i, sizeof(i));
    }
  }
  for (const Texture& t : scene.textures) c.add_vector(t.rgb);
  for (const FloatTexture& t : scene.float_textures) c.add_vector(t.value);
  for (const Light& l : scene.lights) {
    c.add(&l.type, sizeof(l.type));
    c.add(&l.p0, sizeof(l.p0));
    c.add(&l.e1, sizeof(l.e1));
    c.add(&l.e2, sizeof(l.e2));
    c.add(&l.radiance, sizeof(l.radiance));
  }
  // the media and which shapes bound them, the skies' maps and the shapes' alpha (a scene
  // without them adds nothing: the fingerprint of earlier releases)
  for (const Medium& md : scene.media) {
    const float f[] = {md.sigma_a.r, md.sigma_a.g, md.sigma_a.b, md.sigma_s.r, md.sigma_s.g, md.sigma_s.b, md.g, md.Le.r, md.Le.g, md.Le.b};
    c.add(f, sizeof(f));
    const uint8_t supported = md.supported;
    c.add(&supported, 1);
  }
  if (!scene.media.empty()) {
    c.add(&scene.camera_medium, sizeof(scene.camera_medium));
    const auto sides = [&](int inside, int outside) {
      const int32_t m[] = {inside, outside};
      c.add(m, sizeof(m));
    };
    for (const Mesh& m : scene.meshes) sides(m.medium_inside, m.medium_outside);
    for (const Sphere& sp : scene.spheres) sides(sp.medium_inside, sp.medium_outside);
    for (const Curves& cv : scene.curves) sides(cv.medium_inside, cv.medium_outside);
    for (const Light& l : scene.lights)  // (the media point and spot sources sit in)
      if (l.medium >= 0) c.add(&l.medium, sizeof(l.medium));
  }
  for (const SkyMap& m : scene.sky_maps) {
    c.add(&m.res, sizeof(m.res));
    c.add_vector(m.texels);
  }
  for (const Light& l : scene.lights)
    if (l.sky_map >= 0) c.add(&l.sky_map, sizeof(l.sky_map));
  for (const Mesh& m : scene.meshes)
    if (m.has_alpha()) c.add(&m.alpha, sizeof(m.alpha));
  for (const Sphere& sp : scene.spheres)
    if (sp.alpha < 1) c.add(&sp.alpha, sizeof(sp.alpha));
  Estimator est = options.est;
  if (est.sampler != SamplerKind::stratified) est.spp = 0;  // the other samplers do not read spp
  char crc_hex[16];
  std::snprintf(crc_hex, sizeof(crc_hex), "%08lx", static_cast<unsigned long>(c.value));
  std::ostringstream s;
  s << "scene " << scene.source << "\n"
    << "scene-crc32 " << crc_hex << "\n"
    << "resolution " << cam.width << "x" << cam.height << "\n"
    << "estimator " << describe(est) << "\n"
    << "mis-weight-aov " << (est.aov_mis_weight ? 1 : 0) << "\n"
    << (options.filter == FilterParams{} ? "" : "filter " + describe(options.filter) + "\n")  // the default box: as before
    << "passes " << (plan.schedule == PassSchedule::doubling ? "doubling" : "fixed") << " " << plan.pass_spp << "\n";
  return s.str();
}

void save_checkpoint(const std::string& path, const std::string& fingerprint, const PassPlan& plan, const Film& film) {
  write_atomically(path, [&](const std::string& tmp) {
    std::FILE* f = std::fopen(tmp.c_str(), "wb");
    if (!f) throw std::runtime_error(path + ": cannot write the checkpoint");
    try {
      Writer w{f, {}};
      w.bytes(kMagic, sizeof(kMagic));
      w.value(kVersion);
      w.value(static_cast<uint32_t>(fingerprint.size()));
      w.bytes(fingerprint.data(), fingerprint.size());
      w.value(static_cast<uint32_t>(plan.schedule));
      w.value(plan.pass_spp);
      w.value(static_cast<int32_t>(film.width));
      w.value(static_cast<int32_t>(film.height));
      w.value(static_cast<uint64_t>(film.samples));
      w.array(film.sum);
      w.array(film.sum_sq);
      w.array(film.w_sum);
      w.array(film.w_cnt);
      w.array(film.max_sample);
      w.array(film.optimal);  // --heuristic optimal only (9 per pixel); nothing otherwise
      const uint32_t crc = static_cast<uint32_t>(w.crc.value);
      if (std::fwrite(&crc, sizeof(crc), 1, f) != 1) throw std::runtime_error("write failed (disk full?)");
      if (std::fflush(f) != 0 || std::ferror(f)) throw std::runtime_error("write failed (disk full?)");
    } catch (...) {
      std::fclose(f);
      throw;
    }
    if (std::fclose(f) != 0) throw std::runtime_error("write failed (disk full?)");
  });
}

Checkpoint load_checkpoint(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec))
    throw std::runtime_error(path + ": not a checkpoint (not a regular file: a directory or a device)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error(path + ": no checkpoint (render with --checkpoint SECONDS, or interrupt a render, to make one)");
  const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (data.size() < sizeof(kMagic) + 4 || std::memcmp(data.data(), kMagic, sizeof(kMagic)) != 0)
    throw std::runtime_error(path + ": not a tuile checkpoint");
  uint32_t stored = 0;
  std::memcpy(&stored, data.data() + data.size() - 4, 4);
  Crc crc;
  crc.add(data.data(), data.size() - 4);
  if (static_cast<uint32_t>(crc.value) != stored)
    throw std::runtime_error(path + ": checkpoint damaged or cut short (checksum mismatch)");
  Reader r{data, path, sizeof(kMagic)};
  if (r.value<uint32_t>() != kVersion) throw std::runtime_error(path + ": checkpoint of another tuile version");
  Checkpoint c;
  const uint32_t fl = r.value<uint32_t>();
  if (fl > data.size()) throw std::runtime_error(path + ": checkpoint cut short");
  c.fingerprint.resize(fl);
  r.bytes(c.fingerprint.data(), fl);
  c.plan.schedule = static_cast<PassSchedule>(r.value<uint32_t>());
  c.plan.pass_spp = r.value<uint32_t>();
  const int32_t w = r.value<int32_t>(), h = r.value<int32_t>();
  const uint64_t samples = r.value<uint64_t>();
  if (w < 1 || h < 1 || static_cast<uint64_t>(w) * static_cast<uint64_t>(h) > (uint64_t(1) << 28))
    throw std::runtime_error(path + ": checkpoint with an absurd resolution");
  const size_t n = static_cast<size_t>(w) * static_cast<size_t>(h);
  c.film.width = w;
  c.film.height = h;
  c.film.samples = samples;
  r.array(c.film.sum, 3 * n);
  r.array(c.film.sum_sq, 3 * n);
  r.array(c.film.w_sum, n);
  r.array(c.film.w_cnt, n);
  r.array(c.film.max_sample, n);
  if (data.size() - r.at == 4 + 9 * n * sizeof(double)) r.array(c.film.optimal, 9 * n);  // --heuristic optimal's moments
  if (r.at + 4 != data.size()) throw std::runtime_error(path + ": checkpoint has trailing bytes");
  return c;
}

}  // namespace tuile
