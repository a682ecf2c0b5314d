// A shading point's BSDF whatever its material: per lane, the kind of surface (pbrt-v4's
// material types, MaterialKind in src/scene/scene.h) and its parameters, gathered from the
// material table; eval and sample dispatch on the kinds present in the batch (a branch on
// any(), so a batch of one kind runs one BSDF). Bsdfs is the set of kinds a pipeline can
// meet (Features::bsdfs): a pipeline for diffuse scenes compiles Lambert alone.
//
// Frames: Lambert works in world space (the same code, and bits, as a diffuse pipeline);
// the other BSDFs in a local frame whose z is the normal facing the viewer and whose
// tangent is Duff et al.'s basis of that normal (an anisotropic lobe's orientation is
// therefore that basis, not pbrt's dp/du). Dielectrics read which side is inside from
// `side`: +1 where the viewer is on the surface's outside (pbrt's normal side).
#pragma once
#include <type_traits>
#include "bsdf/coated.h"
#include "bsdf/conductor.h"
#include "bsdf/dielectric.h"
#include "bsdf/diffuse_transmission.h"
#include "bsdf/hair.h"
#include "bsdf/lambert.h"
#include "bsdf/thin_dielectric.h"
#include "medium/homogeneous.h"
#include "wave/views.h"

namespace tuile {

template <class T> struct ShadingFrame {
  Vec3<T> t, b, n;
  Vec3<T> to_local(const Vec3<T>& v) const noexcept { return {dot(v, t), dot(v, b), dot(v, n)}; }
  Vec3<T> to_world(const Vec3<T>& v) const noexcept { return t * v.x + b * v.y + n * v.z; }
};

template <class T> inline Rgb3<T> sel_rgb(const mask_t<T>& m, const Rgb3<T>& a, const Rgb3<T>& b) noexcept {
  return {sel(m, a.r, b.r), sel(m, a.g, b.g), sel(m, a.b, b.b)};
}
template <class T> inline void merge(const mask_t<T>& m, const BsdfEval<T>& e, BsdfEval<T>& r) noexcept {
  r.f = sel_rgb(m, e.f, r.f);
  r.pdf = sel(m, e.pdf, r.pdf);
}
template <class T> inline void merge(const mask_t<T>& m, const BsdfSample<T>& s, BsdfSample<T>& r) noexcept {
  r.wi = sel(m, s.wi, r.wi);
  r.weight = sel_rgb(m, s.weight, r.weight);
  r.pdf = sel(m, s.pdf, r.pdf);
  r.delta = sel_mask(m, s.delta, r.delta);
  r.valid = sel_mask(m, s.valid, r.valid);
}

template <class T, unsigned Bsdfs> struct SurfaceBsdf {
  const GeomView* G;
  i32_t<T> mat;   // material per lane
  i32_t<T> kind;  // its MaterialKind
  Rgb3<T> rho;    // reflectance (textured where the material has a texture)
  Vec3<T> n;      // unit normal on the viewer's side
  Vec3<T> wo;     // unit, towards the viewer
  T side;         // +1: the viewer is outside; -1: inside
  T ax, ay;       // Trowbridge-Reitz alphas (conductor, dielectric, the coats): textured or the material's
  Vec3<T> fiber;  // hair: the fiber's axis (unit) and the hit's offset across it (ShadingPoints::fx.., fh)
  T fiber_h;

  T param(int p) const noexcept { return gather(G->mat_param[p], mat); }
  Rgb3<T> param3(int p) const noexcept { return {param(p), param(p + 1), param(p + 2)}; }
  mask_t<T> is(MaterialKind k) const noexcept { return f_mask_from_i(kind == i32_t<T>(static_cast<int32_t>(k))); }
  ShadingFrame<T> frame() const noexcept {
    ShadingFrame<T> f;
    f.n = n;
    make_basis(n, f.t, f.b);
    return f;
  }
  // the dielectric's index below the local frame over the one above (the viewer's side)
  T relative_eta() const noexcept {
    const T eta = param(mp_eta);
    return sel(side > T(0.f), eta, T(1.f) / eta);
  }

  // Hair's frame: x along the fiber (made orthogonal to n; where the two are parallel, the
  // normal's basis), z = n, y = z cross x. Hair reads only azimuth differences, so any
  // rotation about the fiber is the same BSDF; the offset h is measured to match
  // (surface_hits.h apply_hair_frames).
  ShadingFrame<T> hair_frame() const noexcept {
    ShadingFrame<T> f;
    f.n = n;
    Vec3<T> t0, b0;
    make_basis(n, t0, b0);
    const Vec3<T> t = fiber - n * dot(fiber, n);
    const T l2 = dot(t, t);
    const mask_t<T> ok = l2 > T(1e-12f);
    f.t = sel(ok, t * (T(1.f) / sqrt(sel(ok, l2, T(1.f)))), t0);
    f.b = cross(n, f.t);
    return f;
  }
  HairBsdf<T> hair() const noexcept {
    HairBsdf<T> h;
    h.h = fiber_h;
    h.eta = param(mp_eta);
    h.sigma_a = param3(mp_hair_sa_r);
    for (int p = 0; p < 3; ++p) {
      h.inv_v[p] = param(mp_hair_inv_v0 + p);
      h.log_norm[p] = param(mp_hair_log_norm0 + p);
      h.exp_m2v[p] = param(mp_hair_exp_m2v0 + p);
      h.v[p] = param(mp_hair_v0 + p);
      h.sin2k[p] = param(mp_hair_sin0 + p);
      h.cos2k[p] = param(mp_hair_cos0 + p);
    }
    h.s = param(mp_hair_s);
    h.e_pi_s = param(mp_hair_e_pi_s);
    return h;
  }

  // Calls f(bsdf, mask) for each non-diffuse kind present in the batch, with its
  // parameters gathered.
  template <class F> void for_each_local(F&& f) const noexcept {
    if constexpr ((Bsdfs & bsdf_conductor) != 0) {
      const auto m = is(MaterialKind::conductor);
      if (any(m)) f(ConductorBsdf<T>{ax, ay, param3(mp_eta_r), param3(mp_k_r)}, m);
    }
    if constexpr ((Bsdfs & bsdf_dielectric) != 0) {
      const auto m = is(MaterialKind::dielectric);
      if (any(m)) f(DielectricBsdf<T>{relative_eta(), ax, ay}, m);
    }
    if constexpr ((Bsdfs & bsdf_thin_dielectric) != 0) {
      const auto m = is(MaterialKind::thin_dielectric);
      if (any(m)) f(ThinDielectricBsdf<T>{param(mp_eta)}, m);
    }
    if constexpr ((Bsdfs & bsdf_diffuse_transmission) != 0) {
      const auto m = is(MaterialKind::diffuse_transmission);
      if (any(m)) f(DiffuseTransmissionBsdf<T>{rho, param3(mp_tr)}, m);
    }
    if constexpr ((Bsdfs & bsdf_coated_diffuse) != 0) {
      const auto m = is(MaterialKind::coated_diffuse);
      if (any(m))
        f(CoatedDiffuseBsdf<T>{param(mp_eta), ax, ay, rho, param(mp_thickness), param3(mp_alb_r), param3(mp_ri_r)}, m);
    }
    if constexpr ((Bsdfs & bsdf_coated_conductor) != 0) {
      const auto m = is(MaterialKind::coated_conductor);
      if (any(m))
        f(CoatedConductorBsdf<T>{param(mp_eta), ax, ay, param3(mp_eta_r), param3(mp_k_r), param(mp_bax),
                                 param(mp_bay), param(mp_thickness), param3(mp_alb_r)},
          m);
    }
  }

  // f (1/sr) and the pdf sample() draws wi with; 0 for delta lobes.
  BsdfEval<T> eval(const Vec3<T>& wi) const noexcept {
    const Lambert<T> lambert{rho};
    if constexpr (Bsdfs == bsdf_diffuse) {
      return lambert.eval(SurfacePoint<T>{n, wo}, wi);
    } else {
      // one point in a medium (bdpt's and the light tracer's scalar joins): its phase
      // function alone, the value the masked sum below gives it
      if constexpr ((Bsdfs & bsdf_phase) != 0 && std::is_same_v<T, float>)
        if (kind == static_cast<int32_t>(MaterialKind::phase)) {
          const T p = hg_phase(dot(wo, wi), param(mp_hg_g));
          return BsdfEval<T>{{p, p, p}, p};
        }
      BsdfEval<T> r{{T(0.f), T(0.f), T(0.f)}, T(0.f)};
      if constexpr ((Bsdfs & bsdf_diffuse) != 0) {
        const auto m = is(MaterialKind::diffuse);
        if (any(m)) merge(m, lambert.eval(SurfacePoint<T>{n, wo}, wi), r);
      }
      if constexpr ((Bsdfs & ~bsdf_diffuse) != 0) {
        if (!all(is(MaterialKind::diffuse))) {
          const ShadingFrame<T> fr = frame();
          const Vec3<T> wol = fr.to_local(wo), wil = fr.to_local(wi);
          for_each_local([&](const auto& bsdf, const mask_t<T>& m) { merge(m, bsdf.eval(wol, wil), r); });
        }
      }
      if constexpr ((Bsdfs & bsdf_hair) != 0) {
        const auto m = is(MaterialKind::hair);
        if (any(m)) {
          const ShadingFrame<T> fr = hair_frame();
          merge(m, hair().eval(fr.to_local(wo), fr.to_local(wi)), r);
        }
      }
      if constexpr ((Bsdfs & bsdf_phase) != 0) {
        const auto m = is(MaterialKind::phase);
        if (any(m)) {
          const T p = hg_phase(dot(wo, wi), param(mp_hg_g));
          merge(m, BsdfEval<T>{{p, p, p}, p}, r);
        }
      }
      return r;
    }
  }

  // A direction drawn by the BSDF: uc chooses the lobe, (u1, u2) the direction.
  BsdfSample<T> sample(const T& uc, const T& u1, const T& u2) const noexcept {
    const Lambert<T> lambert{rho};
    if constexpr (Bsdfs == bsdf_diffuse) {
      return lambert.sample(SurfacePoint<T>{n, wo}, u1, u2);
    } else {
      BsdfSample<T> r;
      r.wi = n;
      r.weight = {T(0.f), T(0.f), T(0.f)};
      r.pdf = T(0.f);
      r.delta = mask_t<T>(false);
      r.valid = mask_t<T>(false);
      if constexpr ((Bsdfs & bsdf_diffuse) != 0) {
        const auto m = is(MaterialKind::diffuse);
        if (any(m)) merge(m, lambert.sample(SurfacePoint<T>{n, wo}, u1, u2), r);
      }
      if constexpr ((Bsdfs & ~bsdf_diffuse) != 0) {
        if (!all(is(MaterialKind::diffuse))) {
          const ShadingFrame<T> fr = frame();
          const Vec3<T> wol = fr.to_local(wo);
          for_each_local([&](const auto& bsdf, const mask_t<T>& m) {
            BsdfSample<T> s = bsdf.sample(wol, uc, u1, u2);
            s.wi = fr.to_world(s.wi);
            merge(m, s, r);
          });
        }
      }
      if constexpr ((Bsdfs & bsdf_hair) != 0) {
        const auto m = is(MaterialKind::hair);
        if (any(m)) {
          const ShadingFrame<T> fr = hair_frame();
          BsdfSample<T> s = hair().sample(fr.to_local(wo), uc, u1, u2);
          s.wi = fr.to_world(s.wi);
          merge(m, s, r);
        }
      }
      if constexpr ((Bsdfs & bsdf_phase) != 0) {
        const auto m = is(MaterialKind::phase);
        if (any(m)) {
          const PhaseSample<T> ps = sample_hg(wo, param(mp_hg_g), u1, u2);
          BsdfSample<T> s;
          s.wi = ps.wi;
          s.weight = {T(1.f), T(1.f), T(1.f)};  // p / pdf, no cosine
          s.pdf = ps.pdf;
          s.delta = mask_t<T>(false);
          s.valid = ps.pdf > T(0.f);
          merge(m, s, r);
        }
      }
      return r;
    }
  }
};

}  // namespace tuile
