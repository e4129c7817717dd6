// Per-Gaussian preprocessing for the tiled back end, forward and backward, OpenMP over Gaussians:
// the EWA projection of splatting/rasterize.py's project() and the SH colour of
// splatting/sh.py's eval_sh(), the same formulas in the same order (docs/rasterizer.md). In
// torch they are ~60 small autograd ops; fused here they are one pass each way.
//
// Culled Gaussians (z <= near or a degenerate 2D covariance) get radius 0 and no gradient: they
// are never composited, so the compositor hands them none.
//
// The screen-space low-pass eps2d (px^2, added to the 2D covariance's diagonal) is the camera's
// one number, or per Gaussian (eps: N values, or null for the camera's): a scene composes models
// trained with different filters (docs/rasterizer.md). It is a constant, not a parameter: no
// gradient flows to it.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include <immintrin.h>
#include <omp.h>

namespace {

struct Cam {
  double R[9], T[3], centre[3];
  double fx, fy, cx, cy, near, eps2d;
  int W, H;
};

constexpr double SH_C0 = 0.28209479177387814;
constexpr double SH_C1 = 0.4886025119029199;
constexpr double SH_C2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
                             0.5462742152960396};
constexpr double SH_C3[7] = {-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
                             -0.4570457994644658, 1.445305721320277, -0.5900435899266435};

// SH basis (INRIA order) at unit direction (x, y, z); with grad, its derivatives d/dx, d/dy, d/dz.
// S: the scalar type T, or a vector of T (several cameras' directions, one a lane: no derivatives);
// the constants are T either way, so each lane computes what the scalar code does.
template <typename S, typename T = S>
inline void sh_basis(S x, S y, S z, int nb, S* Y, S (*dY)[3]) {
  constexpr bool GRAD = std::is_same<S, T>::value;
  Y[0] = S{} + (T)SH_C0;
  if constexpr (GRAD)
    if (dY) dY[0][0] = dY[0][1] = dY[0][2] = 0;
  if (nb > 1) {
    const T c1 = (T)SH_C1;
    Y[1] = -c1 * y;
    Y[2] = c1 * z;
    Y[3] = -c1 * x;
    if constexpr (GRAD) {
      if (dY) {
        S d[3][3] = {{0, -c1, 0}, {0, 0, c1}, {-c1, 0, 0}};
        for (int k = 0; k < 3; ++k) std::copy(d[k], d[k] + 3, dY[1 + k]);
      }
    }
  }
  if (nb > 4) {
    const S xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    const T* c = nullptr;
    T c2[5];
    for (int k = 0; k < 5; ++k) c2[k] = (T)SH_C2[k];
    c = c2;
    Y[4] = c[0] * xy;
    Y[5] = c[1] * yz;
    Y[6] = c[2] * ((T)2 * zz - xx - yy);
    Y[7] = c[3] * xz;
    Y[8] = c[4] * (xx - yy);
    if constexpr (GRAD) {
      if (dY) {
        S d[5][3] = {{c[0] * y, c[0] * x, 0},
                     {0, c[1] * z, c[1] * y},
                     {c[2] * (S)-2 * x, c[2] * (S)-2 * y, c[2] * (S)4 * z},
                     {c[3] * z, 0, c[3] * x},
                     {c[4] * (S)2 * x, c[4] * (S)-2 * y, 0}};
        for (int k = 0; k < 5; ++k) std::copy(d[k], d[k] + 3, dY[4 + k]);
      }
    }
    if (nb > 9) {
      T c3[7];
      for (int k = 0; k < 7; ++k) c3[k] = (T)SH_C3[k];
      Y[9] = c3[0] * y * ((T)3 * xx - yy);
      Y[10] = c3[1] * xy * z;
      Y[11] = c3[2] * y * ((T)4 * zz - xx - yy);
      Y[12] = c3[3] * z * ((T)2 * zz - (T)3 * xx - (T)3 * yy);
      Y[13] = c3[4] * x * ((T)4 * zz - xx - yy);
      Y[14] = c3[5] * z * (xx - yy);
      Y[15] = c3[6] * x * (xx - (T)3 * yy);
      if constexpr (GRAD) {
        if (dY) {
          S d[7][3] = {{c3[0] * (S)6 * xy, c3[0] * ((S)3 * xx - (S)3 * yy), 0},
                       {c3[1] * yz, c3[1] * xz, c3[1] * xy},
                       {c3[2] * (S)-2 * xy, c3[2] * ((S)4 * zz - xx - (S)3 * yy), c3[2] * (S)8 * yz},
                       {c3[3] * (S)-6 * xz, c3[3] * (S)-6 * yz, c3[3] * ((S)6 * zz - (S)3 * xx - (S)3 * yy)},
                       {c3[4] * ((S)4 * zz - (S)3 * xx - yy), c3[4] * (S)-2 * xy, c3[4] * (S)8 * xz},
                       {c3[5] * (S)2 * xz, c3[5] * (S)-2 * yz, c3[5] * (xx - yy)},
                       {c3[6] * ((S)3 * xx - (S)3 * yy), c3[6] * (S)-6 * xy, 0}};
          for (int k = 0; k < 7; ++k) std::copy(d[k], d[k] + 3, dY[9 + k]);
        }
      }
    }
  }
}

template <typename S>
inline void rotmat(const S* q, S* Rq) {  // unit wxyz -> row-major 3x3
  const S w = q[0], x = q[1], y = q[2], z = q[3];
  Rq[0] = 1 - 2 * (y * y + z * z);
  Rq[1] = 2 * (x * y - w * z);
  Rq[2] = 2 * (x * z + w * y);
  Rq[3] = 2 * (x * y + w * z);
  Rq[4] = 1 - 2 * (x * x + z * z);
  Rq[5] = 2 * (y * z - w * x);
  Rq[6] = 2 * (x * z - w * y);
  Rq[7] = 2 * (y * z + w * x);
  Rq[8] = 1 - 2 * (x * x + y * y);
}

// Everything the backward needs again, recomputed from the inputs (cheaper than storing it).
template <typename S>
struct Geo {
  S p[3], zs, iz, tx, ty, qn[4], qnorm, Rq[9], M[9], RM[9], A0[3], A1[3], a, b, c, det;
  bool valid, clamp_x, clamp_y;
  S lim_x, lim_y;  // the clamp bound hit (signed), when clamped
};

// The camera-independent part of the projection: the unit quaternion, its rotation Rq and the
// 3D covariance's factor M = Rq diag(scale) (cov3d = M M^T). One camera computes it inside
// geometry(); several cameras compute it once per Gaussian (preprocess_fwd_cams), with this same
// code, so every camera's outputs keep the bits of its render alone.
template <typename S>
__attribute__((always_inline)) inline void covariance_factor(const S* quat, const S* scale, S* qn, S& qnorm, S* Rq,
                                                             S* M) {
  qnorm = std::sqrt(quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3]);
  for (int i = 0; i < 4; ++i) qn[i] = quat[i] / qnorm;
  rotmat(qn, Rq);
  for (int j = 0; j < 3; ++j)
    for (int k = 0; k < 3; ++k) M[3 * j + k] = Rq[3 * j + k] * scale[k];
}

// The camera-dependent part of geometry() for a given M (covariance_factor's): camera-space
// mean, clamped Jacobian, A = J R M and the 2D covariance (a, b, c) + eps2d. g.M is not read.
template <typename S>
__attribute__((always_inline)) inline void project_factor(const Cam& cam, const S* mean, const S* M, S e, Geo<S>& g) {
  S R[9], T[3];
  for (int i = 0; i < 9; ++i) R[i] = (S)cam.R[i];
  for (int i = 0; i < 3; ++i) T[i] = (S)cam.T[i];
  for (int i = 0; i < 3; ++i) g.p[i] = R[3 * i] * mean[0] + R[3 * i + 1] * mean[1] + R[3 * i + 2] * mean[2] + T[i];
  const S z = g.p[2];
  g.valid = z > (S)cam.near;
  g.zs = g.valid ? z : (S)1;
  g.iz = (S)1 / g.zs;
  const S fx = (S)cam.fx, fy = (S)cam.fy, W = (S)cam.W, H = (S)cam.H, cx = (S)cam.cx, cy = (S)cam.cy;
  const S lxp = (W - cx) / fx + (S)0.3 * W / ((S)2 * fx), lxn = cx / fx + (S)0.3 * W / ((S)2 * fx);
  const S lyp = (H - cy) / fy + (S)0.3 * H / ((S)2 * fy), lyn = cy / fy + (S)0.3 * H / ((S)2 * fy);
  const S xz = g.p[0] / g.zs, yz = g.p[1] / g.zs;
  g.clamp_x = xz < -lxn || xz > lxp;
  g.clamp_y = yz < -lyn || yz > lyp;
  g.lim_x = xz < -lxn ? -lxn : lxp;
  g.lim_y = yz < -lyn ? -lyn : lyp;
  g.tx = std::min(std::max(xz, -lxn), lxp) * g.zs;
  g.ty = std::min(std::max(yz, -lyn), lyp) * g.zs;
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k)
      g.RM[3 * i + k] = R[3 * i] * M[k] + R[3 * i + 1] * M[3 + k] + R[3 * i + 2] * M[6 + k];
  const S iz = g.iz, iz2 = iz * iz;
  for (int k = 0; k < 3; ++k) {
    g.A0[k] = fx * iz * g.RM[k] - fx * g.tx * iz2 * g.RM[6 + k];
    g.A1[k] = fy * iz * g.RM[3 + k] - fy * g.ty * iz2 * g.RM[6 + k];
  }
  g.a = g.A0[0] * g.A0[0] + g.A0[1] * g.A0[1] + g.A0[2] * g.A0[2] + e;
  g.b = g.A0[0] * g.A1[0] + g.A0[1] * g.A1[1] + g.A0[2] * g.A1[2];
  g.c = g.A1[0] * g.A1[0] + g.A1[1] * g.A1[1] + g.A1[2] * g.A1[2] + e;
  g.det = g.a * g.c - g.b * g.b;
  g.valid = g.valid && g.det > (S)0;
}

template <typename S>
__attribute__((always_inline)) inline void geometry(const Cam& cam, const S* mean, const S* quat, const S* scale, S e,
                                                    Geo<S>& g) {
  covariance_factor(quat, scale, g.qn, g.qnorm, g.Rq, g.M);
  project_factor(cam, mean, g.M, e, g);
}

template <typename S>
inline void direction(const Cam& cam, const S* mean, S* d, S& n) {
  for (int i = 0; i < 3; ++i) d[i] = mean[i] - (S)cam.centre[i];
  n = std::max(std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), (S)1e-12);
  for (int i = 0; i < 3; ++i) d[i] /= n;
}

// Gaussian n's SH colour seen from cam: max(0, sum_k Y_k(view direction) sh_k + 0.5).
template <typename S, int nb>
__attribute__((always_inline)) inline void colour_one(int64_t n, const Cam& cam, const S* means, const S* sh, int K,
                                                      S* colors) {
  S d[3], dn, Y[16];
  direction(cam, means + 3 * n, d, dn);
  sh_basis<S>(d[0], d[1], d[2], nb, Y, nullptr);
  const S* f = sh + n * K * 3;
  for (int ch = 0; ch < 3; ++ch) {
    S acc = 0;
    for (int k = 0; k < nb; ++k) acc += Y[k] * f[3 * k + ch];
    colors[3 * n + ch] = std::max(acc + (S)0.5, (S)0);
  }
}

// nb (the number of SH coefficients used) is a template constant: the SH loops unroll.
// Gaussian n of one camera (the forward's per-Gaussian step, for one camera or several).
// M: Gaussian n's covariance_factor, computed once for several cameras (null: computed here).
template <typename S, int nb, bool COLOUR = true>
__attribute__((always_inline)) inline void preprocess_one(int64_t n, const Cam& cam, const S* means, const S* quats,
                                                          const S* scales, const S* sh, const S* eps, int K,
                                                          S* means2d, S* conics, S* depths, S* colors,
                                                          int64_t* radii, int64_t* boxes, bool* visible,
                                                          const S* M = nullptr) {
  {
    Geo<S> g;
    if (M)
      project_factor(cam, means + 3 * n, M, eps ? eps[n] : (S)cam.eps2d, g);
    else
      geometry(cam, means + 3 * n, quats + 4 * n, scales + 3 * n, eps ? eps[n] : (S)cam.eps2d, g);
    const S u = (S)cam.fx * g.p[0] / g.zs + (S)cam.cx, v = (S)cam.fy * g.p[1] / g.zs + (S)cam.cy;
    means2d[2 * n] = u;
    means2d[2 * n + 1] = v;
    depths[n] = g.p[2];
    const S det = g.valid ? g.det : (S)1;
    conics[3 * n] = g.c / det;
    conics[3 * n + 1] = -g.b / det;
    conics[3 * n + 2] = g.a / det;
    const S mid = (S)0.5 * (g.a + g.c);
    const S lam = mid + std::sqrt(std::max(mid * mid - g.det, (S)0.1));
    // non-finite input (NaN / inf parameters) is culled rather than turned into garbage boxes
    const bool ok = g.valid && std::isfinite(u) && std::isfinite(v) && std::isfinite(lam);
    const S r = ok ? std::ceil((S)3 * std::sqrt(lam)) : (S)0;
    const S mu = ok ? std::min(std::max(u, (S)-1e7), (S)1e7) : (S)-1e7;  // culled: an empty box
    const S mv = ok ? std::min(std::max(v, (S)-1e7), (S)1e7) : (S)-1e7;
    const S u0 = std::min(std::max(std::ceil(mu - r - (S)0.5), (S)0), (S)cam.W);
    const S u1 = std::min(std::max(std::floor(mu + r - (S)0.5), (S)-1), (S)(cam.W - 1));
    const S v0 = std::min(std::max(std::ceil(mv - r - (S)0.5), (S)0), (S)cam.H);
    const S v1 = std::min(std::max(std::floor(mv + r - (S)0.5), (S)-1), (S)(cam.H - 1));
    int64_t* bx = boxes + 4 * n;
    bx[0] = (int64_t)u0, bx[1] = (int64_t)u1, bx[2] = (int64_t)v0, bx[3] = (int64_t)v1;
    radii[n] = (ok && bx[1] >= bx[0] && bx[3] >= bx[2]) ? (int64_t)r : 0;
    visible[n] = radii[n] > 0;
    if (COLOUR) colour_one<S, nb>(n, cam, means, sh, K, colors);
  }
}

template <typename S, int nb>
void preprocess_fwd(int64_t N, const Cam& cam, const S* means, const S* quats, const S* scales, const S* sh,
                    const S* eps, int K, int nt, S* means2d, S* conics, S* depths, S* colors, int64_t* radii,
                    int64_t* boxes, bool* visible) {
#pragma omp parallel for num_threads(nt) schedule(dynamic, 2048)  // a late thread delays by one block
  for (int64_t n = 0; n < N; ++n)
    preprocess_one<S, nb>(n, cam, means, quats, scales, sh, eps, K, means2d, conics, depths, colors, radii, boxes,
                          visible);
}

// ---- several cameras, one camera a vector lane (forward only) ----
// Lanes<S>: 8 float or 4 double lanes (AVX), with std::min / std::max / ceil / floor / sqrt /
// isfinite lane-wise exactly as the scalar ones (the same comparisons, IEEE sqrt and rounding).
template <typename S>
struct Lanes {
  typedef S V __attribute__((vector_size(32)));
  static constexpr int L = 32 / sizeof(S);
#ifdef __AVX__
  static V sqrt(V x) {
    if constexpr (sizeof(S) == 4) return (V)_mm256_sqrt_ps((__m256)x);
    else return (V)_mm256_sqrt_pd((__m256d)x);
  }
  template <int MODE>  // _MM_FROUND_TO_POS_INF: ceil, _MM_FROUND_TO_NEG_INF: floor
  static V round(V x) {
    if constexpr (sizeof(S) == 4) return (V)_mm256_round_ps((__m256)x, MODE | _MM_FROUND_NO_EXC);
    else return (V)_mm256_round_pd((__m256d)x, MODE | _MM_FROUND_NO_EXC);
  }
  static V ceil(V x) { return round<_MM_FROUND_TO_POS_INF>(x); }
  static V floor(V x) { return round<_MM_FROUND_TO_NEG_INF>(x); }
#else  // lane by lane: the same results, without the speed
  static V sqrt(V x) { for (int l = 0; l < L; ++l) x[l] = std::sqrt(x[l]); return x; }
  static V ceil(V x) { for (int l = 0; l < L; ++l) x[l] = std::ceil(x[l]); return x; }
  static V floor(V x) { for (int l = 0; l < L; ++l) x[l] = std::floor(x[l]); return x; }
#endif
};
template <typename V> inline V vmax(V a, V b) { return a < b ? b : a; }  // std::max(a, b)
template <typename V> inline V vmin(V a, V b) { return b < a ? b : a; }  // std::min(a, b)

// Up to L cameras' constants, lane l = camera l (lanes past nc repeat camera 0: computed, not
// written). The same conversions and formulas as geometry() / preprocess_one() take per Gaussian.
template <typename S>
struct CamLanes {
  typedef typename Lanes<S>::V V;
  V R[9], T[3], centre[3], fx, fy, cx, cy, near, eps2d, W, H, W1, H1, lxp, lxn, lyp, lyn;
  int nc;
  CamLanes(const Cam* cams, int n) : nc(n) {
    for (int l = 0; l < Lanes<S>::L; ++l) {
      const Cam& cam = cams[l < n ? l : 0];
      for (int i = 0; i < 9; ++i) R[i][l] = (S)cam.R[i];
      for (int i = 0; i < 3; ++i) T[i][l] = (S)cam.T[i], centre[i][l] = (S)cam.centre[i];
      const S fx_ = (S)cam.fx, fy_ = (S)cam.fy, W_ = (S)cam.W, H_ = (S)cam.H, cx_ = (S)cam.cx, cy_ = (S)cam.cy;
      fx[l] = fx_, fy[l] = fy_, cx[l] = cx_, cy[l] = cy_, W[l] = W_, H[l] = H_;
      W1[l] = (S)(cam.W - 1), H1[l] = (S)(cam.H - 1);
      near[l] = (S)cam.near, eps2d[l] = (S)cam.eps2d;
      lxp[l] = (W_ - cx_) / fx_ + (S)0.3 * W_ / ((S)2 * fx_), lxn[l] = cx_ / fx_ + (S)0.3 * W_ / ((S)2 * fx_);
      lyp[l] = (H_ - cy_) / fy_ + (S)0.3 * H_ / ((S)2 * fy_), lyn[l] = cy_ / fy_ + (S)0.3 * H_ / ((S)2 * fy_);
    }
  }
};

// preprocess_one without the colour for the cameras of cl at once: Gaussian n (mean, its
// covariance_factor M, its eps2d or null for the cameras'), each camera's outputs at c * N.
// Line for line project_factor() and preprocess_one() on lanes, so each lane has the bits of the
// scalar code (tests/test_rasterization_cameras.py checks it).
template <typename S>
__attribute__((always_inline)) inline void project_lanes(int64_t n, const CamLanes<S>& cl, int64_t N, const S* mean,
                                                         const S* M, const S* eps, S* means2d, S* conics, S* depths,
                                                         int64_t* radii, int64_t* boxes, bool* visible) {
  typedef Lanes<S> LN;
  typedef typename LN::V V;
  const V one = (V){} + (S)1, zero = (V){};
  V p[3];
  for (int i = 0; i < 3; ++i) p[i] = cl.R[3 * i] * mean[0] + cl.R[3 * i + 1] * mean[1] + cl.R[3 * i + 2] * mean[2] + cl.T[i];
  const V z = p[2];
  auto valid = z > cl.near;
  const V zs = valid ? z : one;
  const V iz = one / zs;
  const V xz = p[0] / zs, yz = p[1] / zs;
  const V tx = vmin(vmax(xz, -cl.lxn), cl.lxp) * zs;
  const V ty = vmin(vmax(yz, -cl.lyn), cl.lyp) * zs;
  V RM[9];
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) RM[3 * i + k] = cl.R[3 * i] * M[k] + cl.R[3 * i + 1] * M[3 + k] + cl.R[3 * i + 2] * M[6 + k];
  const V iz2 = iz * iz;
  V A0[3], A1[3];
  for (int k = 0; k < 3; ++k) {
    A0[k] = cl.fx * iz * RM[k] - cl.fx * tx * iz2 * RM[6 + k];
    A1[k] = cl.fy * iz * RM[3 + k] - cl.fy * ty * iz2 * RM[6 + k];
  }
  const V e = eps ? (V){} + *eps : cl.eps2d;
  const V a = A0[0] * A0[0] + A0[1] * A0[1] + A0[2] * A0[2] + e;
  const V b = A0[0] * A1[0] + A0[1] * A1[1] + A0[2] * A1[2];
  const V c = A1[0] * A1[0] + A1[1] * A1[1] + A1[2] * A1[2] + e;
  const V gdet = a * c - b * b;
  valid = valid & (gdet > zero);
  // preprocess_one
  const V u = cl.fx * p[0] / zs + cl.cx, v = cl.fy * p[1] / zs + cl.cy;
  const V det = valid ? gdet : one;
  const V cn0 = c / det, cn1 = -b / det, cn2 = a / det;
  const V mid = (S)0.5 * (a + c);
  const V lam = mid + LN::sqrt(vmax(mid * mid - gdet, (V){} + (S)0.1));
  const auto ok = valid & ((u - u) == zero) & ((v - v) == zero) & ((lam - lam) == zero);  // isfinite
  const V r = ok ? LN::ceil((S)3 * LN::sqrt(lam)) : zero;
  const V lo = (V){} + (S)-1e7, hi = (V){} + (S)1e7;
  const V mu = ok ? vmin(vmax(u, lo), hi) : lo;
  const V mv = ok ? vmin(vmax(v, lo), hi) : lo;
  const V u0 = vmin(vmax(LN::ceil(mu - r - (S)0.5), zero), cl.W);
  const V u1 = vmin(vmax(LN::floor(mu + r - (S)0.5), -one), cl.W1);
  const V v0 = vmin(vmax(LN::ceil(mv - r - (S)0.5), zero), cl.H);
  const V v1 = vmin(vmax(LN::floor(mv + r - (S)0.5), -one), cl.H1);
  for (int l = 0; l < cl.nc; ++l) {
    const int64_t i = l * N + n;
    means2d[2 * i] = u[l];
    means2d[2 * i + 1] = v[l];
    depths[i] = z[l];
    conics[3 * i] = cn0[l];
    conics[3 * i + 1] = cn1[l];
    conics[3 * i + 2] = cn2[l];
    int64_t* bx = boxes + 4 * i;
    bx[0] = (int64_t)u0[l], bx[1] = (int64_t)u1[l], bx[2] = (int64_t)v0[l], bx[3] = (int64_t)v1[l];
    radii[i] = (ok[l] && bx[1] >= bx[0] && bx[3] >= bx[2]) ? (int64_t)r[l] : 0;
    visible[i] = radii[i] > 0;
  }
}

// colour_one() for the cameras of cl at once: each lane's view direction and SH basis as the
// scalar code computes them (direction(), sh_basis on lanes), the Gaussian's coefficients read
// once and the sums lane by lane in the scalar loop's order (one FMA a term).
template <typename S, int nb>
__attribute__((always_inline)) inline void colour_lanes(int64_t n, const CamLanes<S>& cl, int64_t N, const S* means,
                                                        const S* sh, int K, S* colors) {
  typedef Lanes<S> LN;
  typedef typename LN::V V;
  const S* mean = means + 3 * n;
  V d[3];
  for (int i = 0; i < 3; ++i) d[i] = mean[i] - cl.centre[i];
  const V dn = vmax(LN::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), (V){} + (S)1e-12);
  for (int i = 0; i < 3; ++i) d[i] /= dn;
  V Y[16];
  sh_basis<V, S>(d[0], d[1], d[2], nb, Y, nullptr);
  const S* f = sh + n * K * 3;
  for (int ch = 0; ch < 3; ++ch) {
    V acc = (V){};
    for (int k = 0; k < nb; ++k) acc += Y[k] * f[3 * k + ch];
    const V c = vmax(acc + (S)0.5, (V){});
    for (int l = 0; l < cl.nc; ++l) colors[3 * (l * N + n) + ch] = c[l];
  }
}

// C cameras at once: one parallel loop over blocks of PRE_BLOCK Gaussians; per block the
// camera-independent covariance factor M of each Gaussian once (covariance_factor), then every
// camera's projection and SH colour of the block while its inputs are still in L1/L2 (the colour
// of up to L cameras per Gaussian at once, colour_lanes). Outputs camera-major (camera c's at c * N).
constexpr int64_t PRE_BLOCK = 256;

template <typename S, int nb>
void preprocess_fwd_cams(int C, int64_t N, const Cam* cams, const S* means, const S* quats, const S* scales,
                         const S* sh, const S* eps, int K, int nt, S* means2d, S* conics, S* depths, S* colors,
                         int64_t* radii, int64_t* boxes, bool* visible) {
  const int64_t NB = (N + PRE_BLOCK - 1) / PRE_BLOCK;
  // the colour camera-lane-wise (colour_lanes) from degree 2 on; below, the per-camera loop is
  // faster (measured, 50k, 4 cameras, one thread: degree 0 3.7 against 3.9 ms, degree 1 3.8
  // against 4.3)
  constexpr bool LANES = nb >= 9;
  constexpr int L = Lanes<S>::L;
  std::vector<CamLanes<S>> groups;
  for (int c = 0; c < C; c += L) groups.emplace_back(cams + c, std::min(L, C - c));
#pragma omp parallel for num_threads(nt) schedule(dynamic, 1)
  for (int64_t blk = 0; blk < NB; ++blk) {
    const int64_t b = blk * PRE_BLOCK, e = std::min(b + PRE_BLOCK, N);
    S M[9 * PRE_BLOCK], qn[4], qnorm, Rq[9];
    for (int64_t n = b; n < e; ++n) covariance_factor(quats + 4 * n, scales + 3 * n, qn, qnorm, Rq, M + 9 * (n - b));
    for (int gi = 0; gi < (int)groups.size(); ++gi) {
      const int64_t o = (int64_t)gi * L * N;
      for (int64_t n = b; n < e; ++n)
        project_lanes<S>(n, groups[gi], N, means + 3 * n, M + 9 * (n - b), eps ? eps + n : nullptr, means2d + 2 * o,
                         conics + 3 * o, depths + o, radii + o, boxes + 4 * o, visible + o);
    }
    if (LANES)
      for (int gi = 0; gi < (int)groups.size(); ++gi)
        for (int64_t n = b; n < e; ++n)
          colour_lanes<S, nb>(n, groups[gi], N, means, sh, K, colors + 3 * (int64_t)gi * L * N);
    else
      for (int c = 0; c < C; ++c)
        for (int64_t n = b; n < e; ++n) colour_one<S, nb>(n, cams[c], means, sh, K, colors + 3 * c * N);
  }
}

// nb (the number of SH coefficients used) is a template constant: the SH loops unroll.
// A null incoming gradient (an output nobody used) counts as zeros.
template <typename S, int nb>
void preprocess_bwd(int64_t N, const Cam& cam, const S* means, const S* quats, const S* scales, const S* sh,
                    const S* eps, int K, int nt, const int64_t* radii, const S* g_means2d, const S* g_conics,
                    const S* g_depths, const S* g_colors, S* g_means, S* g_quats, S* g_scales, S* g_sh) {
#pragma omp parallel for num_threads(nt) schedule(dynamic, 2048)  // a late thread delays by one block
  for (int64_t n = 0; n < N; ++n) {
    S* gm = g_means + 3 * n;
    gm[0] = gm[1] = gm[2] = 0;
    std::fill_n(g_quats + 4 * n, 4, (S)0);
    std::fill_n(g_scales + 3 * n, 3, (S)0);
    std::fill_n(g_sh + n * K * 3, K * 3, (S)0);
    if (radii[n] <= 0) continue;  // never composited: nothing flows back
    // hidden behind other Gaussians' cut-off or too faint everywhere: every incoming gradient is
    // zero, and so is every outgoing one (about half of a dense bike part's Gaussians)
    const S zero3[3] = {0, 0, 0};
    const S* const gm2 = g_means2d ? g_means2d + 2 * n : zero3;
    const S* const gcn = g_conics ? g_conics + 3 * n : zero3;
    const S* const gcol = g_colors ? g_colors + 3 * n : zero3;
    const S gdep = g_depths ? g_depths[n] : (S)0;
    bool any_grad = gdep != (S)0;
    for (int i = 0; i < 2; ++i) any_grad |= gm2[i] != (S)0;
    for (int i = 0; i < 3; ++i) any_grad |= (gcn[i] != (S)0) | (gcol[i] != (S)0);
    if (!any_grad) continue;
    // ---- colour: rgb = max(0, sum_k Y_k sh_k + 0.5)
    S d[3], dn, Y[16], dY[16][3];
    direction(cam, means + 3 * n, d, dn);
    sh_basis<S>(d[0], d[1], d[2], nb, Y, dY);
    const S* f = sh + n * K * 3;
    S* gf = g_sh + n * K * 3;
    S gd[3] = {0, 0, 0};
    for (int ch = 0; ch < 3; ++ch) {
      S acc = 0;
      for (int k = 0; k < nb; ++k) acc += Y[k] * f[3 * k + ch];
      const S gc = (acc + (S)0.5 >= (S)0) ? gcol[ch] : (S)0;
      if (gc == (S)0) continue;
      for (int k = 0; k < nb; ++k) {
        gf[3 * k + ch] = Y[k] * gc;
        for (int i = 0; i < 3; ++i) gd[i] += dY[k][i] * f[3 * k + ch] * gc;
      }
    }
    if (dn > (S)1e-12) {  // through d / |d|
      const S dot = gd[0] * d[0] + gd[1] * d[1] + gd[2] * d[2];
      for (int i = 0; i < 3; ++i) gm[i] += (gd[i] - d[i] * dot) / dn;
    }
    // ---- geometry
    Geo<S> g;
    geometry(cam, means + 3 * n, quats + 4 * n, scales + 3 * n, eps ? eps[n] : (S)cam.eps2d, g);
    const S fx = (S)cam.fx, fy = (S)cam.fy, iz = g.iz, iz2 = iz * iz;
    S gp[3] = {0, 0, 0}, g_iz = 0, g_tx = 0, g_ty = 0;
    // means2d = (fx x / zs + cx, fy y / zs + cy)
    const S gu = gm2[0], gv = gm2[1];
    gp[0] += fx * iz * gu;
    gp[1] += fy * iz * gv;
    g_iz += fx * g.p[0] * gu + fy * g.p[1] * gv;
    gp[2] += gdep;
    // conic = (c, -b, a) / det
    const S det = g.det, id = (S)1 / det, id2 = id * id;
    const S gA = gcn[0], gB = gcn[1], gC = gcn[2];
    const S a = g.a, b = g.b, c = g.c;
    const S ga = gA * (-c * c * id2) + gB * (b * c * id2) + gC * (id - a * c * id2);
    const S gb = gA * ((S)2 * b * c * id2) + gB * (-id - (S)2 * b * b * id2) + gC * ((S)2 * a * b * id2);
    const S gcc = gA * (id - c * a * id2) + gB * (a * b * id2) + gC * (-a * a * id2);
    S gA0[3], gA1[3], gR[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};  // gR: d/d RM (rows r0, r1, r2)
    for (int k = 0; k < 3; ++k) {
      gA0[k] = (S)2 * ga * g.A0[k] + gb * g.A1[k];
      gA1[k] = (S)2 * gcc * g.A1[k] + gb * g.A0[k];
    }
    S r2A0 = 0, r2A1 = 0, r0A0 = 0, r1A1 = 0;
    for (int k = 0; k < 3; ++k) {
      gR[k] += fx * iz * gA0[k];
      gR[6 + k] += -fx * g.tx * iz2 * gA0[k] - fy * g.ty * iz2 * gA1[k];
      gR[3 + k] += fy * iz * gA1[k];
      r0A0 += g.RM[k] * gA0[k];
      r2A0 += g.RM[6 + k] * gA0[k];
      r1A1 += g.RM[3 + k] * gA1[k];
      r2A1 += g.RM[6 + k] * gA1[k];
    }
    g_iz += fx * r0A0 - (S)2 * fx * g.tx * iz * r2A0 + fy * r1A1 - (S)2 * fy * g.ty * iz * r2A1;
    g_tx += -fx * iz2 * r2A0;
    g_ty += -fy * iz2 * r2A1;
    // tx = clamp(x / zs) * zs: x itself inside the clamp, bound * zs outside
    S g_zs = -iz2 * g_iz;
    if (g.clamp_x) g_zs += g.lim_x * g_tx; else gp[0] += g_tx;
    if (g.clamp_y) g_zs += g.lim_y * g_ty; else gp[1] += g_ty;
    if (g.valid) gp[2] += g_zs;  // zs = z (valid is true here: radius > 0)
    S R[9];
    for (int i = 0; i < 9; ++i) R[i] = (S)cam.R[i];
    for (int j = 0; j < 3; ++j) gm[j] += R[j] * gp[0] + R[3 + j] * gp[1] + R[6 + j] * gp[2];
    // RM = R M -> gM = R^T gRM; M = Rq diag(s)
    S gM[9], gRq[9];
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) gM[3 * j + k] = R[j] * gR[k] + R[3 + j] * gR[3 + k] + R[6 + j] * gR[6 + k];
    const S* s = scales + 3 * n;
    S* gs = g_scales + 3 * n;
    for (int k = 0; k < 3; ++k) {
      gs[k] = gM[k] * g.Rq[k] + gM[3 + k] * g.Rq[3 + k] + gM[6 + k] * g.Rq[6 + k];
      for (int j = 0; j < 3; ++j) gRq[3 * j + k] = gM[3 * j + k] * s[k];
    }
    const S w = g.qn[0], x = g.qn[1], y = g.qn[2], z = g.qn[3];
    const S* G = gRq;
    S gq[4];
    gq[0] = 2 * (-z * G[1] + y * G[2] + z * G[3] - x * G[5] - y * G[6] + x * G[7]);
    gq[1] = 2 * (y * G[1] + z * G[2] + y * G[3] - 2 * x * G[4] - w * G[5] + z * G[6] + w * G[7] - 2 * x * G[8]);
    gq[2] = 2 * (-2 * y * G[0] + x * G[1] + w * G[2] + x * G[3] + z * G[5] - w * G[6] + z * G[7] - 2 * y * G[8]);
    gq[3] = 2 * (-2 * z * G[0] - w * G[1] + x * G[2] + w * G[3] - 2 * z * G[4] + y * G[5] + x * G[6] + y * G[7]);
    const S dot = gq[0] * g.qn[0] + gq[1] * g.qn[1] + gq[2] * g.qn[2] + gq[3] * g.qn[3];
    for (int i = 0; i < 4; ++i) g_quats[4 * n + i] = (gq[i] - g.qn[i] * dot) / g.qnorm;
  }
}

Cam make_cam(const double* R, const double* T, const double* intr, int W, int H) {
  Cam c;
  std::copy(R, R + 9, c.R);
  std::copy(T, T + 3, c.T);
  for (int i = 0; i < 3; ++i) c.centre[i] = -(R[i] * T[0] + R[3 + i] * T[1] + R[6 + i] * T[2]);  // -R^T T
  c.fx = intr[0], c.fy = intr[1], c.cx = intr[2], c.cy = intr[3], c.near = intr[4], c.eps2d = intr[5];
  c.W = W, c.H = H;
  return c;
}

}  // namespace

// nb in {1, 4, 9, 16} (checked by the caller, splatting/raster/cpu_project.py)
#define SH_DISPATCH(nb, F, S, ...)         \
  switch (nb) {                            \
    case 1: F<S, 1>(__VA_ARGS__); break;   \
    case 4: F<S, 4>(__VA_ARGS__); break;   \
    case 9: F<S, 9>(__VA_ARGS__); break;   \
    default: F<S, 16>(__VA_ARGS__); break; \
  }

extern "C" {

// cam_R (9, row-major), cam_T (3), intr = (fx, fy, cx, cy, near, eps2d), all float64.
// sh: (N, K, 3) contiguous; the first nb = (degree + 1)^2 coefficients are used.
// eps2d: (N,) per-Gaussian low-pass, or null for intr's one value.
#define GS_PRE_EXPORT(SUFFIX, S)                                                                   \
  void gs_preprocess_fwd_##SUFFIX(int64_t N, const double* R, const double* T, const double* intr, \
                                  int W, int H, const S* means, const S* quats, const S* scales,    \
                                  const S* sh, const S* eps2d, int K, int nb, int nt, S* means2d,   \
                                  S* conics, S* depths, S* colors, int64_t* radii, int64_t* boxes,  \
                                  bool* visible) {                                                  \
    const Cam cam = make_cam(R, T, intr, W, H);                                                     \
    SH_DISPATCH(nb, preprocess_fwd, S, N, cam, means, quats, scales, sh, eps2d, K, nt, means2d, conics, \
                depths, colors, radii, boxes, visible);                                             \
  }                                                                                                 \
  void gs_preprocess_bwd_##SUFFIX(int64_t N, const double* R, const double* T, const double* intr, \
                                  int W, int H, const S* means, const S* quats, const S* scales,    \
                                  const S* sh, const S* eps2d, int K, int nb, int nt,               \
                                  const int64_t* radii,                                             \
                                  const S* g_means2d, const S* g_conics, const S* g_depths,         \
                                  const S* g_colors, S* g_means, S* g_quats, S* g_scales,           \
                                  S* g_sh) {                                                        \
    const Cam cam = make_cam(R, T, intr, W, H);                                                     \
    SH_DISPATCH(nb, preprocess_bwd, S, N, cam, means, quats, scales, sh, eps2d, K, nt, radii, g_means2d, \
                g_conics, g_depths, g_colors, g_means, g_quats, g_scales, g_sh);                    \
  }

GS_PRE_EXPORT(f32, float)
GS_PRE_EXPORT(f64, double)

// C cameras of one size W x H: cam_R (C, 9), cam_T (C, 3), intr (C, 6) as above; outputs (C, N, ...).
#define GS_PRE_CAMS_EXPORT(SUFFIX, S)                                                                    \
  void gs_preprocess_fwd_cams_##SUFFIX(int C, int64_t N, const double* R, const double* T, const double* intr, \
                                       int W, int H, const S* means, const S* quats, const S* scales,     \
                                       const S* sh, const S* eps2d, int K, int nb, int nt, S* means2d,    \
                                       S* conics, S* depths, S* colors, int64_t* radii, int64_t* boxes,   \
                                       bool* visible) {                                                   \
    std::vector<Cam> cams(C);                                                                             \
    for (int c = 0; c < C; ++c) cams[c] = make_cam(R + 9 * c, T + 3 * c, intr + 6 * c, W, H);              \
    SH_DISPATCH(nb, preprocess_fwd_cams, S, C, N, cams.data(), means, quats, scales, sh, eps2d, K, nt, means2d, \
                conics, depths, colors, radii, boxes, visible);                                           \
  }

GS_PRE_CAMS_EXPORT(f32, float)
GS_PRE_CAMS_EXPORT(f64, double)

}  // extern "C"
