// Tiled CPU compositing of projected Gaussians, forward and backward (the structure of the
// INRIA CUDA rasterizer: per-tile binning, depth order inside each tile, front-to-back blending
// per pixel with early termination, and a back-to-front backward), OpenMP over tiles.
//
// Plain C ABI (called through ctypes from splatting/raster/cpu_tiles.py): no torch headers, so
// it builds in seconds with g++ and does not depend on torch's C++ ABI. Image formation is the
// one of splatting/rasterize.py (docs/rasterizer.md), bit for bit in its decisions where
// possible:
//   pixel (u, v) is touched by Gaussian g when it lies in g's 3-sigma box [u0,u1]x[v0,v1] and
//   alpha_raw = o exp(-sigma) >= 1/255, sigma = 0.5 (A dx^2 + C dy^2) + B dx dy,
//   d = pixel centre - mean; alpha = min(alpha_raw, 0.99); the step that takes T below 1e-4 is
//   not taken, nor any after it.
// Every Gaussian carries Cf channels (colour, extra features, depth: the caller decides).
//
// Built with -ffp-contract=off: forward and backward must reach the same alpha test decisions
// from the same expressions, which FMA contraction in one loop and not the other could break.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <type_traits>
#ifdef __AVX__
#include <immintrin.h>
#endif

#include <omp.h>

// splatting/relight/csrc/shade.cpp (built into the same library): the relit shading as a tile epilogue
extern "C" int rl_shade_tile_f32(const float* acc, int Cf, const float* T, int tile, int ox, int oy, int ex, int ey,
                                 int64_t W, float* out, const float* prm, int32_t flags);
extern "C" int rl_shade_tile_channels(int32_t flags);

namespace {

constexpr int TILE = 16;
constexpr int TPIX = TILE * TILE;

// Tile t's pixels, [ox, ex] x [oy, ey] inclusive, clipped to the W x H image (TX tiles per row):
// the forward and the backward walk the same tiles.
struct TileRect {
  int ox, oy, ex, ey;
  TileRect(int t, int TX, int W, int H)
      : ox(t % TX * TILE), oy(t / TX * TILE), ex(std::min(ox + TILE, W) - 1), ey(std::min(oy + TILE, H) - 1) {}
};
constexpr double ALPHA_MIN = 1.0 / 255.0;
constexpr double ALPHA_MAX = 0.99;
constexpr double T_MIN = 1e-4;
constexpr double MARGIN = 1e-3;
// Tile-list entries the record / feature prefetch runs ahead (8, 24 and 48 measured alike).
constexpr int PF = 8;  // px: the ellipse's bounding box is widened by this against rounding

// SIMD over the pixels of a tile row with GCC vector extensions (AVX2 with -march=native: 8
// floats or 4 doubles; SSE or NEON pairs elsewhere). Lanes never mix, so a pixel's result is
// the same whichever lane computes it: forward and backward take identical decisions.
template <typename S> struct VT;
template <> struct VT<float> {
  typedef float V __attribute__((vector_size(32)));
  typedef int32_t I __attribute__((vector_size(32)));
  static constexpr int L = 8;
};
template <> struct VT<double> {
  typedef double V __attribute__((vector_size(32)));
  typedef int64_t I __attribute__((vector_size(32)));
  static constexpr int L = 4;
};

// lane masks -> bits (movemask with AVX; a lane loop elsewhere)
template <typename I>
inline unsigned bits(I m) {
#ifdef __AVX__
  if (sizeof(m[0]) == 4) return (unsigned)_mm256_movemask_ps((__m256)m);
  return (unsigned)_mm256_movemask_pd((__m256d)m);
#else
  unsigned b = 0;
  for (int l = 0; l < (int)(sizeof(I) / sizeof(m[0])); ++l) b |= (m[l] != 0) << l;
  return b;
#endif
}
template <typename I>
inline bool any(I m) { return bits(m) != 0; }
template <typename I>
inline int count(I m) { return __builtin_popcount(bits(m)); }

// a * b + c, fused where the CPU has FMA. Explicit, so -ffp-contract=off elsewhere still keeps
// the compiler from fusing the forward's and the backward's copies of an expression differently;
// these fuse in both alike.
inline VT<float>::V vfma(VT<float>::V a, VT<float>::V b, VT<float>::V c) {
#ifdef __FMA__
  return (VT<float>::V)_mm256_fmadd_ps((__m256)a, (__m256)b, (__m256)c);
#else
  return a * b + c;
#endif
}
inline VT<double>::V vfma(VT<double>::V a, VT<double>::V b, VT<double>::V c) {
#ifdef __FMA__
  return (VT<double>::V)_mm256_fmadd_pd((__m256d)a, (__m256d)b, (__m256d)c);
#else
  return a * b + c;
#endif
}

// exp for float lanes: Cephes expf (range reduction by ln 2, degree-5 polynomial, |rel err| <
// 2e-7 on the range used here: -sigma in [-88, 0]). Vectorises where the libm call would not.
inline VT<float>::V vexp(VT<float>::V x) {
  typedef VT<float>::V V;
  typedef VT<float>::I I;
  const V one = (V){} + 1.0f;
  x = x < (V){} - 87.0f ? (V){} - 87.0f : x;
  x = x > (V){} + 88.0f ? (V){} + 88.0f : x;
#ifdef __AVX__
  const V fn = (V)_mm256_floor_ps((__m256)(x * 1.44269504088896341f + 0.5f));
  const I n = __builtin_convertvector(fn, I);
#else
  V fx = x * 1.44269504088896341f + 0.5f;
  I n = __builtin_convertvector(fx, I);
  V fn = __builtin_convertvector(n, V);
  n = fn > fx ? n - 1 : n;  // floor
  fn = __builtin_convertvector(n, V);
#endif
  V r = vfma(fn, (V){} - 0.693359375f, x);
  r = vfma(fn, (V){} + 2.12194440e-4f, r);
  V y = vfma((V){} + 1.9875691500e-4f, r, (V){} + 1.3981999507e-3f);
  y = vfma(y, r, (V){} + 8.3334519073e-3f);
  y = vfma(y, r, (V){} + 4.1665795894e-2f);
  y = vfma(y, r, (V){} + 1.6666665459e-1f);
  y = vfma(y, r, (V){} + 5.0000001201e-1f);
  y = vfma(y, r * r, r + one);
  I e = (n + 127) << 23;
  V scale;
  __builtin_memcpy(&scale, &e, sizeof(V));
  return y * scale;
}

// double lanes (the float64 path: tests, gradcheck): libm exp per lane, exact to the ulp.
inline VT<double>::V vexp(VT<double>::V x) {
  VT<double>::V r;
  for (int l = 0; l < 4; ++l) r[l] = std::exp(x[l]);
  return r;
}

template <typename S>
struct alignas(64) Rec {  // one visible Gaussian; one cache line (float) for the prefetch
  S mx, my, a, b, c, o, tau;  // mean (px), conic, opacity, tau = ln(255 o) + TAU_PAD
  int32_t u0, u1, v0, v1;     // pixels: the 3-sigma box clipped to the sigma <= tau ellipse's box
};

// sigma <= tau is only a cheap pre-test (skips the exp and whole tiles); the decision is the
// alpha test itself, so tau is padded to stay clear of rounding.
constexpr double TAU_PAD = 1e-3;

// dst[b] = the sum of v[b]'s lanes, b < n (v padded with zero vectors to a multiple of 8). For
// 8 float vectors at a time: a transpose-and-add with hadd/permute instead of 56 scalar adds.
inline void hsum(const VT<float>::V* v, int n, float* dst) {
  for (int b = 0; b < n; b += 8) {
#ifdef __AVX__
    const __m256* x = (const __m256*)(v + b);
    const __m256 ab = _mm256_hadd_ps(_mm256_hadd_ps(x[0], x[1]), _mm256_hadd_ps(x[2], x[3]));
    const __m256 cd = _mm256_hadd_ps(_mm256_hadd_ps(x[4], x[5]), _mm256_hadd_ps(x[6], x[7]));
    alignas(32) float r[8];
    _mm256_store_ps(r, _mm256_add_ps(_mm256_permute2f128_ps(ab, cd, 0x20), _mm256_permute2f128_ps(ab, cd, 0x31)));
    for (int i = 0; i < 8 && b + i < n; ++i) dst[b + i] = r[i];
#else
    for (int i = 0; i < 8 && b + i < n; ++i) {
      float h = 0;
      for (int l = 0; l < 8; ++l) h += v[b + i][l];
      dst[b + i] = h;
    }
#endif
  }
}
inline void hsum(const VT<double>::V* v, int n, double* dst) {
  for (int b = 0; b < n; ++b) dst[b] = (v[b][0] + v[b][1]) + (v[b][2] + v[b][3]);
}

// One (tile, Gaussian) entry as both passes see it: its pixel rows and 8-lane chunks inside the
// tile, the per-lane dx and in-box masks (set up once per entry, not per chunk), and
// sigma = (a/2 dx + b dy) dx + c/2 dy^2 with two FMAs per chunk. The forward and the backward
// evaluate sigma and alpha_raw = o exp(-sigma) through this one code path, so they take
// bit-identical alpha decisions.
template <typename S>
struct Entry {
  typedef typename VT<S>::V V;
  typedef typename VT<S>::I I;
  static constexpr int L = VT<S>::L, NJ = TILE / L;
  V ha, dx[NJ];
  I box[NJ];
  int y0, y1, j0, j1;
  // lane_xc[j]: lane l of chunk j holds j * L + l + 0.5 (a pixel centre's offset in the tile);
  // built once per thread by lane_centres()
  static std::vector<V> lane_centres() {
    std::vector<V> xc(NJ);
    for (int j = 0; j < NJ; ++j)
      for (int l = 0; l < L; ++l) xc[j][l] = (S)(j * L + l) + (S)0.5;
    return xc;
  }
  Entry(const Rec<S>& g, int ox, int oy, int ex, int ey, const V* lane_xc) {
    y0 = std::max(oy, g.v0);
    y1 = std::min(ey, g.v1);
    const int xa = std::max(ox, g.u0), xb = std::min(ex, g.u1);
    j0 = (xa - ox) / L;
    j1 = (xb - ox) / L;
    ha = (V){} + (S)0.5 * g.a;
    for (int j = j0; j <= j1; ++j) {
      const V xc = lane_xc[j] + (S)ox;  // exact: small integers + 0.5
      dx[j] = xc - g.mx;
      box[j] = (xc > (S)xa) & (xc < (S)(xb + 1));
    }
  }
  // per row: dy, and the row's terms b dy, c/2 dy^2 (broadcast)
  static inline S row(const Rec<S>& g, int y, V& by, V& cyy) {
    const S dy = (S)y + (S)0.5 - g.my;
    by = (V){} + g.b * dy;
    cyy = (V){} + (S)0.5 * g.c * dy * dy;
    return dy;
  }
  inline V sigma(int j, V by, V cyy) const { return vfma(vfma(ha, dx[j], by), dx[j], cyy); }
  static inline V alpha_raw(const Rec<S>& g, V sigma) { return g.o * vexp(-sigma); }
};

inline int64_t clampi(double x, int64_t lo, int64_t hi) {
  if (!(x >= (double)lo)) return lo;  // also NaN
  if (x > (double)hi) return hi;
  return (int64_t)x;
}

template <typename S>
void make_rec(Rec<S>& r, int64_t gi, const S* means2d, const S* conics, const S* opac,
              const int64_t* radii, const int64_t* boxes, int W, int H) {
  r.mx = means2d[2 * gi];
  r.my = means2d[2 * gi + 1];
  r.a = conics[3 * gi];
  r.b = conics[3 * gi + 1];
  r.c = conics[3 * gi + 2];
  r.o = opac[gi];
  r.tau = r.o > (S)0 ? std::log((S)255 * r.o) + (S)TAU_PAD : (S)-1;
  r.u0 = r.v0 = 0;
  r.u1 = r.v1 = -1;
  const double det = (double)r.a * r.c - (double)r.b * r.b;
  if (radii[gi] <= 0 || !(r.tau > (S)TAU_PAD) || !(det > 0) || !(r.a > (S)0)) return;
  // bounding box of the ellipse sigma <= tau, clipped to the 3-sigma box (itself inside the image)
  const double ex = std::sqrt(2.0 * (double)r.tau * (double)r.c / det);
  const double ey = std::sqrt(2.0 * (double)r.tau * (double)r.a / det);
  const int64_t* bx = boxes + 4 * gi;
  r.u0 = (int32_t)std::max<int64_t>(std::max(bx[0], clampi(std::ceil((double)r.mx - ex - 0.5 - MARGIN), 0, W)), 0);
  r.u1 = (int32_t)std::min<int64_t>(std::min(bx[1], clampi(std::floor((double)r.mx + ex - 0.5 + MARGIN), -1, W - 1)), W - 1);
  r.v0 = (int32_t)std::max<int64_t>(std::max(bx[2], clampi(std::ceil((double)r.my - ey - 0.5 - MARGIN), 0, H)), 0);
  r.v1 = (int32_t)std::min<int64_t>(std::min(bx[3], clampi(std::floor((double)r.my + ey - 0.5 + MARGIN), -1, H - 1)), H - 1);
}

inline void chunk(int64_t n, int nt, int th, int64_t& b, int64_t& e) {
  b = n * th / nt;
  e = n * (th + 1) / nt;
}

// The depth order is binned and filled in CHUNKS_PER_THREAD * nt contiguous chunks handed out
// dynamically, not one chunk per thread: on a shared machine a thread that starts late (its core
// busy with another process) then delays the other by one small chunk, not by half the work at the
// barrier. Each chunk has its own tile cursors (cursor: chunks x tiles), so the tile lists come
// out the same for any thread count or schedule.
constexpr int CHUNKS_PER_THREAD = 8;
inline int n_chunks(int nt) { return CHUNKS_PER_THREAD * std::max(nt, 1); }
// Gaussians per dynamically scheduled block of per-Gaussian loops (same reason).
constexpr int64_t GAUSS_BLOCK = 2048;

// body(s, e, cur) for every position s of the depth order [0, nv), chunk by chunk: the chunks are
// shared out among the threads of the enclosing parallel region (an orphaned omp for, with its
// barrier at the end unless LAST: the end of the parallel region waits anyway, and under
// OMP_WAIT_POLICY=PASSIVE every extra barrier is a sleep and a wake-up, ~50 us each on this VM);
// e is the chunk's end, cur its tile cursors (cursor + chunk * NT).
template <bool LAST = false, typename F>
inline void over_chunks(int64_t nv, int NC, int64_t* cursor, int NT, F&& body) {
  auto one = [&](int c) {
    int64_t b, e;
    chunk(nv, NC, c, b, e);
    int64_t* const cur = cursor + (int64_t)c * NT;
    for (int64_t s = b; s < e; ++s) body(s, e, cur);
  };
  if (LAST) {
#pragma omp for schedule(dynamic, 1) nowait
    for (int c = 0; c < NC; ++c) one(c);
  } else {
#pragma omp for schedule(dynamic, 1)
    for (int c = 0; c < NC; ++c) one(c);
  }
}

// Order-preserving unsigned keys of floats (negative values flipped).
inline uint32_t fkey(float x) {
  uint32_t u;
  __builtin_memcpy(&u, &x, 4);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}
inline uint64_t fkey(double x) {
  uint64_t u;
  __builtin_memcpy(&u, &x, 8);
  return (u & 0x8000000000000000ull) ? ~u : (u | 0x8000000000000000ull);
}

// Stable LSD radix sort of (key, idx)[0, n) by key, 11-bit digits, using k2 / i2 as scratch; the
// result ends in key / idx. The histograms of every digit come from one pass, and a digit that all
// keys share is skipped (no scatter). Stable + indices entering in increasing order = ties in
// index order, like torch.argsort(stable=True) in the torch path.
template <typename K>
void radix_sort(int64_t n, K* key, int32_t* idx, K* k2, int32_t* i2) {
  constexpr int D = (8 * sizeof(K) + 10) / 11;
  std::vector<int32_t> cnt((size_t)D << 11, 0);
  for (int64_t i = 0; i < n; ++i)
    for (int d = 0; d < D; ++d) cnt[((size_t)d << 11) + ((key[i] >> (11 * d)) & 2047)]++;
  for (int d = 0; d < D; ++d) {
    int32_t* const c = cnt.data() + ((size_t)d << 11);
    if (n == 0 || c[(key[0] >> (11 * d)) & 2047] == n) continue;  // one bucket: already in order
    int32_t pos = 0;
    for (int b = 0; b < 2048; ++b) {
      const int32_t t = c[b];
      c[b] = pos;
      pos += t;
    }
    for (int64_t i = 0; i < n; ++i) {
      const int32_t at = c[(key[i] >> (11 * d)) & 2047]++;
      k2[at] = key[i];
      i2[at] = idx[i];
    }
    std::copy_n(k2, n, key);  // keep the run in place (a few us; simpler than tracking the swaps)
    std::copy_n(i2, n, idx);
  }
}

// Phase 1: the visible Gaussians (radii > 0) sorted by depth into order, their records in that
// order (recs[s] for Gaussian order[s]), rank (N) the inverse (rank[order[s]] = s; -1: not visible);
// tile counts per chunk of that order, tile offsets, per-Gaussian entry offsets (goff, in depth
// order). cursor (n_chunks(nt) x ntiles) becomes each chunk's first write position per tile.
// sizes[0] = visible count nv, sizes[1] = number of (tile, Gaussian) entries.
// The depth sort is serial (a parallel LSD sort with a barrier per digit lost: ~12 sleeps and
// wake-ups under OMP_WAIT_POLICY=PASSIVE; per-thread sorts and a merge lost too, docs/rasterizer.md)
// but it needs only radii and depths, so one thread sorts while the others start on the records,
// and it joins them (dynamic blocks) when it is done: no extra barrier, the same order.
template <typename S>
void bin(int64_t N, const S* means2d, const S* conics, const S* opac, const S* depths,
         const int64_t* radii, const int64_t* boxes, int W, int H, int nt, Rec<S>* recs,
         int32_t* order, int32_t* rank, int64_t* cursor, int64_t* tile_off, int64_t* goff, int64_t* sizes) {
  const int TX = (W + TILE - 1) / TILE, TY = (H + TILE - 1) / TILE, NT = TX * TY;
  typedef decltype(fkey(S())) K;
  const int NC = n_chunks(nt);
  // records computed in index order (sequential reads), then gathered into depth order: one
  // random read per Gaussian here, and sequential or monotonic reads everywhere after
  // reused across calls (no page faults per frame); thread_local is the calling thread's, so the
  // OpenMP threads use it through plain pointers
  static thread_local std::vector<Rec<S>> by_index_buf;
  static thread_local std::vector<K> key_buf;
  static thread_local std::vector<int32_t> idx_buf;
  if ((int64_t)by_index_buf.size() < N) {
    by_index_buf.resize(N);
    key_buf.resize(2 * N);
    idx_buf.resize(2 * N);
  }
  Rec<S>* const by_index = by_index_buf.data();
  K* const key = key_buf.data();
  int32_t* const idx = idx_buf.data();
  int64_t nv = 0;
  std::fill(cursor, cursor + (int64_t)NC * NT, 0);
#pragma omp parallel num_threads(nt)
  {
#pragma omp single nowait
    {
      int64_t m = 0;
      for (int64_t i = 0; i < N; ++i)
        if (radii[i] > 0) {
          key[m] = fkey(depths[i]);
          idx[m++] = (int32_t)i;
        }
      radix_sort(m, key, idx, key + N, idx + N);
      std::copy_n(idx, m, order);
      nv = m;
    }
#pragma omp for schedule(dynamic, GAUSS_BLOCK)
    for (int64_t i = 0; i < N; ++i) {
      make_rec(by_index[i], i, means2d, conics, opac, radii, boxes, W, H);
      if (radii[i] <= 0) rank[i] = -1;
    }
    // (the loop's barrier also waits for the sort: order and nv are complete after it)
    over_chunks<true>(nv, NC, cursor, NT, [&](int64_t s, int64_t e, int64_t* cnt) {
      if (s + 16 < e) __builtin_prefetch(by_index + order[s + 16]);  // the gather's misses overlap
      rank[order[s]] = (int32_t)s;
      const Rec<S>& r = recs[s] = by_index[order[s]];
      if (r.u1 < r.u0 || r.v1 < r.v0) {
        goff[s + 1] = 0;
        return;
      }
      const int tx0 = r.u0 / TILE, tx1 = r.u1 / TILE, ty0 = r.v0 / TILE, ty1 = r.v1 / TILE;
      for (int ty = ty0; ty <= ty1; ++ty)
        for (int tx = tx0; tx <= tx1; ++tx) cnt[ty * TX + tx]++;
      goff[s + 1] = (int64_t)(tx1 - tx0 + 1) * (ty1 - ty0 + 1);
    });
  }
  goff[0] = 0;
  for (int64_t s = 0; s < nv; ++s) goff[s + 1] += goff[s];
  int64_t pos = 0;
  for (int t = 0; t < NT; ++t) {
    tile_off[t] = pos;
    for (int ch = 0; ch < NC; ++ch) {
      const int64_t c = cursor[(int64_t)ch * NT + t];
      cursor[(int64_t)ch * NT + t] = pos;
      pos += c;
    }
  }
  tile_off[NT] = pos;
  sizes[0] = nv;
  sizes[1] = pos;
}

// Tiles by decreasing list length (ties in index order): handed out in that order by the dynamic
// schedule, the longest tiles start first and the short ones fill in at the end, so no thread is
// left finishing one long tile while the other waits (longest-processing-time-first).
inline std::vector<int> busiest_first(const int64_t* tile_off, int NT) {
  std::vector<int> order(NT);
  for (int t = 0; t < NT; ++t) order[t] = t;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return tile_off[a + 1] - tile_off[a] > tile_off[b + 1] - tile_off[b];
  });
  return order;
}

// Copy L lanes of a vector to dst[0..n) (n < L at the image's right edge).
template <typename V, typename T>
inline void store_lanes(T* dst, const V& v, int n) {
  if (n * sizeof(T) == sizeof(V)) {
    __builtin_memcpy(dst, &v, sizeof(V));
    return;
  }
  for (int l = 0; l < n; ++l) dst[l] = (T)v[l];
}

// The Cf channels of a pixel as n consecutive planes: plane q holds size[q] channels per pixel,
// pixel-major (H x W x size[q]), so each output the caller wants apart (colour, extra features,
// depth) is its own contiguous image and its gradient comes back the same way: no strided slicing
// of one interleaved image (and no zero-filled full-size gradient for the channels nobody used).
// P: S* for the outputs, const S* for their gradients (a null plane: no gradient).
template <typename P>
struct Planes {
  int n;
  const int* size;
  const P* ptr;
};

// Per-thread scratch of blend_tile: a tile's transmittance, finished lanes, last contributors and
// accumulated channels, and with groups each group's own transmittance and finished lanes.
template <typename S>
struct BlendScratch {
  typedef typename VT<S>::V V;
  typedef typename VT<S>::I I;
  static constexpr int NV = TPIX / VT<S>::L;
  std::vector<V> lane_xc, T, acc, fv, TG;
  std::vector<I> done, lst, gdone;
  BlendScratch(int Cf, int NG)
      : lane_xc(Entry<S>::lane_centres()), T(NV), acc((size_t)NV * Cf), fv(Cf), TG((size_t)NG * NV), done(NV),
        lst(NV), gdone((size_t)NG * NV) {}
};

// Blend tile t front to back for forward_cameras (its n list entries list_t, with recs and feats in
// depth order): writes the tile's pixels of the out planes and alpha, T_final and last where not
// null, with GROUPS the group alphas. The same steps as forward()'s tile loop, whose copy stays
// inline there: calling this from forward() made its blend 1-3 % slower at one thread (CPU time,
// three alternating pairs), so a single camera's render keeps its code and speed;
// tests/test_rasterization_cameras.py checks that the two give the same bits.
template <typename S, bool GROUPS, int CF>
__attribute__((always_inline)) inline void blend_tile(int t, int TX, int W, int H, int Cf_, const Rec<S>* recs,
                                                      const int32_t* list_t, int64_t n, const S* feats,
                                                      Planes<S*> out, S* T_final, S* alpha, int32_t* last,
                                                      int NG, const int32_t* grp, S* A_grp, const S* bg,
                                                      const float* shade_prm, int32_t shade_flags,
                                                      BlendScratch<S>& sc) {
  typedef typename VT<S>::V V;
  typedef typename VT<S>::I I;
  typedef typename std::remove_reference<decltype(I{}[0])>::type IS;
  constexpr int L = VT<S>::L, NV = TPIX / L, NJ = TILE / L;
  const int Cf = CF > 0 ? CF : Cf_;
  // separate buffers: __restrict lets the compiler keep their values in registers across stores
  const V* __restrict const lane_xc = sc.lane_xc.data();
  V* __restrict const T = sc.T.data();
  V* __restrict const acc_p = sc.acc.data();
  V* __restrict const fv = sc.fv.data();
  V* __restrict const TG = sc.TG.data();
  I* __restrict const done = sc.done.data();
  I* __restrict const lst = sc.lst.data();
  I* __restrict const gdone = sc.gdone.data();
  const auto [ox, oy, ex, ey] = TileRect(t, TX, W, H);
  if (n == 0) {  // empty (most tiles of a bike image): nothing to blend
    for (int y = oy; y <= ey; ++y) {
      const int64_t p = (int64_t)y * W + ox, nx = ex - ox + 1;
      if (T_final) std::fill_n(T_final + p, nx, (S)1);
      std::fill_n(alpha + p, nx, (S)0);
      if (last) std::fill_n(last + p, nx, 0);
      for (int q = 0; q < out.n; ++q)
        if (out.ptr[q]) std::fill_n(out.ptr[q] + p * out.size[q], nx * out.size[q], (S)0);
      if (bg)
        for (int64_t i = 0; i < nx; ++i)
          for (int c = 0; c < out.size[0]; ++c) out.ptr[0][(p + i) * out.size[0] + c] = (S)0 + (S)1 * bg[c];
      for (int q = 0; q < (GROUPS ? NG : 0); ++q) std::fill_n(A_grp + (int64_t)q * H * W + p, nx, (S)0);
    }
    return;
  }
  int active = 0;
  for (int v = 0; v < NV; ++v) {
    T[v] = (V){} + (S)1;
    lst[v] = (I){};
    for (int l = 0; l < L; ++l) {
      const int i = v * L + l;
      const bool inside = ox + i % TILE <= ex && oy + i / TILE <= ey;
      done[v][l] = inside ? 0 : -1;
      active += inside;
    }
  }
  if (GROUPS)
    for (int q = 0; q < NG; ++q)
      for (int v = 0; v < NV; ++v) {
        TG[(size_t)q * NV + v] = (V){} + (S)1;
        gdone[(size_t)q * NV + v] = done[v];
      }
  std::fill_n(acc_p, (size_t)NV * Cf, (V){});
  // with groups the list is walked to its end: a group's pixels close only when its own
  // transmittance runs out, and pixels that no Gaussian of a group reaches never do
  for (int64_t k = 0; k < n && (GROUPS || active > 0); ++k) {
    if (k + PF < n) {
      __builtin_prefetch(recs + list_t[k + PF]);
      __builtin_prefetch(feats + (int64_t)list_t[k + PF] * Cf);
    }
    const int32_t sp = list_t[k];
    const Rec<S>& g = recs[sp];
    const int q = GROUPS ? grp[sp] : -1;
    if (GROUPS && q < 0 && active == 0) continue;
    V* const Tq = q >= 0 ? TG + (size_t)q * NV : nullptr;
    I* const dq = q >= 0 ? gdone + (size_t)q * NV : nullptr;
    const Entry<S> en(g, ox, oy, ex, ey, lane_xc);
    const S* f = feats + (int64_t)sp * Cf;
    for (int c = 0; c < Cf; ++c) fv[c] = (V){} + f[c];  // broadcast once per entry, not per chunk
    const I kk = (I){} + (IS)(k + 1);
    for (int y = en.y0; y <= en.y1; ++y) {
      V by, cyy;
      Entry<S>::row(g, y, by, cyy);
      for (int j = en.j0; j <= en.j1; ++j) {
        const int v = (y - oy) * NJ + j;
        const I live = GROUPS && q >= 0 ? en.box[j] & ~(done[v] & dq[v]) : en.box[j] & ~done[v];
        if (!any(live)) continue;  // finished pixels: no sigma, no exp
        const V sigma = en.sigma(j, by, cyy);
        const I pre = live & (sigma <= g.tau);
        if (!any(pre)) continue;
        const V ar = Entry<S>::alpha_raw(g, sigma);
        const I mg = pre & (ar >= (S)ALPHA_MIN);
        if (!any(mg)) continue;
        const V al = ar < (S)ALPHA_MAX ? ar : (V){} + (S)ALPHA_MAX;
        if (GROUPS && q >= 0) {  // the group alone: the same steps on its own transmittance
          const I mq = mg & ~dq[v];
          const V test_q = Tq[v] * ((S)1 - al);
          const I term_q = mq & (test_q < (S)T_MIN);
          dq[v] |= term_q;
          Tq[v] = (mq & ~term_q) ? test_q : Tq[v];
        }
        const I m = GROUPS ? mg & ~done[v] : mg;  // without groups live already excludes done
        if (GROUPS && !any(m)) continue;
        const V test_T = T[v] * ((S)1 - al);
        const I term = m & (test_T < (S)T_MIN);
        if (any(term)) {
          done[v] |= term;
          active -= count(term);
        }
        const I ok = m & ~term;
        const V w = ok ? al * T[v] : (V){};
        V* a = acc_p + (size_t)v * Cf;
        for (int c = 0; c < Cf; ++c) a[c] = vfma(w, fv[c], a[c]);
        T[v] = ok ? test_T : T[v];
        lst[v] = ok ? kk : lst[v];
      }
    }
  }
  if constexpr (std::is_same<S, float>::value)
    if (shade_prm)  // (Cf checked by the caller, gs_forward)
      rl_shade_tile_f32((const float*)acc_p, Cf, (const float*)T, TILE, ox, oy, ex, ey, W,
                        out.ptr[0], shade_prm, shade_flags);
  for (int y = oy; y <= ey; ++y)
    for (int j = 0; j < NJ && ox + j * L <= ex; ++j) {
      const int v = (y - oy) * NJ + j, nl = std::min(L, ex - (ox + j * L) + 1);
      const int64_t p = (int64_t)y * W + ox + j * L;
      for (int q = 0; q < (GROUPS ? NG : 0); ++q)
        store_lanes(A_grp + (int64_t)q * H * W + p, (S)1 - TG[(size_t)q * NV + v], nl);
      if (T_final) store_lanes(T_final + p, T[v], nl);
      store_lanes(alpha + p, (S)1 - T[v], nl);
      if (!last) {
      } else if (sizeof(IS) == 4) {
        store_lanes(last + p, lst[v], nl);
      } else {
        for (int l = 0; l < nl; ++l) last[p + l] = (int32_t)lst[v][l];
      }
      const V* a = acc_p + (size_t)v * Cf;
      for (int q = 0, c0 = 0; q < out.n; c0 += out.size[q++]) {  // pixel-major per plane
        const int cq = out.size[q];
        if (!out.ptr[q] || (q == 0 && shade_prm)) continue;  // not wanted, or shaded above
        S* __restrict const o = out.ptr[q] + p * cq;
        if (q == 0 && bg) {  // over the background: c + T_final bg (as rgb + T_final * bg in torch)
          for (int l = 0; l < nl; ++l)
            for (int c = 0; c < cq; ++c) o[l * cq + c] = a[c][l] + T[v][l] * bg[c];
          continue;
        }
        if (cq == 1) {  // one channel (depth): the lanes are the pixels
          store_lanes(o, a[c0], nl);
          continue;
        }
        for (int l = 0; l < nl; ++l)
          for (int c = 0; c < cq; ++c) o[l * cq + c] = a[c0 + c][l];
      }
    }
}

// Phase 2: fill the tile lists with depth-order positions (depth order kept: each thread writes
// its depth-ordered chunk after the chunks in front of it), gather the Cf channels into depth
// order (feats, from the input Planes in: plane q holds size[q] channels per Gaussian, so the
// caller's colour, features and depth need no concatenation), then blend every tile front to back.
// out: the Cf channels as Planes, T_final and alpha = 1 - T_final (H x W), last (H x W): per
// pixel 1 + the tile-list position of its last contributor (0: none). T_final, last and slot
// may be null: only the backward reads them (a no-grad render skips ~3 MB of cold stores).
// GROUPS (forward only, no backward): every Gaussian also belongs to one of NG groups (grp_in,
// per input Gaussian; -1: none), and A_grp (NG x H x W) gets each group's alpha (1 - its
// transmittance) as if its Gaussians were rendered alone (no occlusion by the others: the amodal
// alpha of an instance), with the same per-pixel rules (alpha test, clamp, the step that would take T
// below 1e-4 not taken). One pass: the alpha a Gaussian has at a pixel is computed once for the
// image and its group, and a pixel's list is walked past the image's own cut-off only while
// some group at that pixel is still open. grp (nv): the groups gathered into depth order.
// CF > 0: the channel count as a compile-time constant (the per-pixel channel loop unrolls, its
// per-Gaussian broadcasts stay in registers); CF == 0: any Cf. in: the input parts, per Gaussian
// (their sizes sum to Cf; several may make up one output plane).
// An output plane whose pointer is null is not written (a channel the caller composites only to
// shade it). shade_prm (float only; null: none): the relit shading of csrc/shade.cpp as the tile's
// epilogue (rl_shade_tile_f32, flags shade_flags): plane 0 (3 channels, the reflectance) receives
// the display colour shaded from the tile's accumulated reflectance and relight features (the
// channels after it), so neither needs to be written and read back (docs/relighting.md).
template <typename S, bool GROUPS, int CF>
void forward(int64_t nv, const int32_t* order, Planes<const S*> in, int Cf_, int W, int H, int nt,
             const Rec<S>* recs, int64_t* cursor, const int64_t* tile_off, const int64_t* goff,
             int32_t* list, int64_t* slot, S* feats, Planes<S*> out, S* T_final, S* alpha, int32_t* last,
             const int32_t* grp_in, int NG, int32_t* grp, S* A_grp, const S* bg, const float* shade_prm,
             int32_t shade_flags) {
  const int Cf = CF > 0 ? CF : Cf_;
  const int TX = (W + TILE - 1) / TILE, TY = (H + TILE - 1) / TILE, NT = TX * TY;
  const std::vector<int> torder = busiest_first(tile_off, NT);
  const int NC = n_chunks(nt);
#pragma omp parallel num_threads(nt)
  {
    over_chunks(nv, NC, cursor, NT, [&](int64_t s, int64_t e, int64_t* cur) {
      const int64_t gi = order[s], gn = s + 16 < e ? order[s + 16] : gi;
      for (int q = 0, c0 = 0; q < in.n; c0 += in.size[q++]) {
        const int cq = in.size[q];
        __builtin_prefetch(in.ptr[q] + gn * cq);
        // a few channels: plain moves (std::copy_n was a memmove call per Gaussian and part)
        const S* src = in.ptr[q] + gi * cq;
        S* dst = feats + s * Cf + c0;
        int c = 0;
        for (; c + 4 <= cq; c += 4) dst[c] = src[c], dst[c + 1] = src[c + 1], dst[c + 2] = src[c + 2], dst[c + 3] = src[c + 3];
        for (; c < cq; ++c) dst[c] = src[c];
      }
      if (GROUPS) grp[s] = grp_in[order[s]];
      const Rec<S>& r = recs[s];
      if (r.u1 < r.u0 || r.v1 < r.v0) return;
      int64_t k = goff[s];
      for (int ty = r.v0 / TILE; ty <= r.v1 / TILE; ++ty)
        for (int tx = r.u0 / TILE; tx <= r.u1 / TILE; ++tx) {
          const int64_t p = cur[ty * TX + tx]++;
          list[p] = (int32_t)s;
          if (slot) slot[p] = k++;
        }
    });  // (over_chunks ends with a barrier: every list is filled before any tile blends)
    typedef typename VT<S>::V V;
    typedef typename VT<S>::I I;
    typedef typename std::remove_reference<decltype(I{}[0])>::type IS;
    constexpr int L = VT<S>::L, NV = TPIX / L, NJ = TILE / L;
    const std::vector<V> lane_xc = Entry<S>::lane_centres();
    std::vector<V> T(NV);
    std::vector<I> done(NV), lst(NV);
    std::vector<V> acc((size_t)NV * Cf), fv(Cf);
    std::vector<V> TG(GROUPS ? (size_t)NG * NV : 0);  // per group and pixel: its own transmittance
    std::vector<I> gdone(GROUPS ? (size_t)NG * NV : 0);
#pragma omp for schedule(dynamic, 1) nowait  // the region's end is the barrier
    for (int it = 0; it < NT; ++it) {
      const int t = torder[it];
      const auto [ox, oy, ex, ey] = TileRect(t, TX, W, H);
      if (tile_off[t + 1] == tile_off[t]) {  // empty (most tiles of a bike image): nothing to blend
        for (int y = oy; y <= ey; ++y) {
          const int64_t p = (int64_t)y * W + ox, nx = ex - ox + 1;
          if (T_final) std::fill_n(T_final + p, nx, (S)1);
          std::fill_n(alpha + p, nx, (S)0);
          if (last) std::fill_n(last + p, nx, 0);
          for (int q = 0; q < out.n; ++q)
            if (out.ptr[q]) std::fill_n(out.ptr[q] + p * out.size[q], nx * out.size[q], (S)0);
          if (bg)
            for (int64_t i = 0; i < nx; ++i)
              for (int c = 0; c < out.size[0]; ++c) out.ptr[0][(p + i) * out.size[0] + c] = (S)0 + (S)1 * bg[c];
          for (int q = 0; q < (GROUPS ? NG : 0); ++q) std::fill_n(A_grp + (int64_t)q * H * W + p, nx, (S)0);
        }
        continue;
      }
      int active = 0;
      for (int v = 0; v < NV; ++v) {
        T[v] = (V){} + (S)1;
        lst[v] = (I){};
        for (int l = 0; l < L; ++l) {
          const int i = v * L + l;
          const bool inside = ox + i % TILE <= ex && oy + i / TILE <= ey;
          done[v][l] = inside ? 0 : -1;
          active += inside;
        }
      }
      if (GROUPS)
        for (int q = 0; q < NG; ++q)
          for (int v = 0; v < NV; ++v) {
            TG[(size_t)q * NV + v] = (V){} + (S)1;
            gdone[(size_t)q * NV + v] = done[v];
          }
      std::fill(acc.begin(), acc.end(), (V){});
      const int64_t t0 = tile_off[t], n = tile_off[t + 1] - t0;
      // with groups the list is walked to its end: a group's pixels close only when its own
      // transmittance runs out, and pixels that no Gaussian of a group reaches never do
      for (int64_t k = 0; k < n && (GROUPS || active > 0); ++k) {
        if (k + PF < n) {
          __builtin_prefetch(recs + list[t0 + k + PF]);
          __builtin_prefetch(feats + (int64_t)list[t0 + k + PF] * Cf);
        }
        const int32_t sp = list[t0 + k];
        const Rec<S>& g = recs[sp];
        const int q = GROUPS ? grp[sp] : -1;
        if (GROUPS && q < 0 && active == 0) continue;
        V* const Tq = q >= 0 ? TG.data() + (size_t)q * NV : nullptr;
        I* const dq = q >= 0 ? gdone.data() + (size_t)q * NV : nullptr;
        const Entry<S> en(g, ox, oy, ex, ey, lane_xc.data());
        const S* f = feats + (int64_t)sp * Cf;
        for (int c = 0; c < Cf; ++c) fv[c] = (V){} + f[c];  // broadcast once per entry, not per chunk
        const I kk = (I){} + (IS)(k + 1);
        for (int y = en.y0; y <= en.y1; ++y) {
          V by, cyy;
          Entry<S>::row(g, y, by, cyy);
          for (int j = en.j0; j <= en.j1; ++j) {
            const int v = (y - oy) * NJ + j;
            const I live = GROUPS && q >= 0 ? en.box[j] & ~(done[v] & dq[v]) : en.box[j] & ~done[v];
            if (!any(live)) continue;  // finished pixels: no sigma, no exp
            const V sigma = en.sigma(j, by, cyy);
            const I pre = live & (sigma <= g.tau);
            if (!any(pre)) continue;
            const V ar = Entry<S>::alpha_raw(g, sigma);
            const I mg = pre & (ar >= (S)ALPHA_MIN);
            if (!any(mg)) continue;
            const V al = ar < (S)ALPHA_MAX ? ar : (V){} + (S)ALPHA_MAX;
            if (GROUPS && q >= 0) {  // the group alone: the same steps on its own transmittance
              const I mq = mg & ~dq[v];
              const V test_q = Tq[v] * ((S)1 - al);
              const I term_q = mq & (test_q < (S)T_MIN);
              dq[v] |= term_q;
              Tq[v] = (mq & ~term_q) ? test_q : Tq[v];
            }
            const I m = GROUPS ? mg & ~done[v] : mg;  // without groups live already excludes done
            if (GROUPS && !any(m)) continue;
            const V test_T = T[v] * ((S)1 - al);
            const I term = m & (test_T < (S)T_MIN);
            if (any(term)) {
              done[v] |= term;
              active -= count(term);
            }
            const I ok = m & ~term;
            const V w = ok ? al * T[v] : (V){};
            V* a = acc.data() + (size_t)v * Cf;
            for (int c = 0; c < Cf; ++c) a[c] = vfma(w, fv[c], a[c]);
            T[v] = ok ? test_T : T[v];
            lst[v] = ok ? kk : lst[v];
          }
        }
      }
      if constexpr (std::is_same<S, float>::value)
        if (shade_prm)  // (Cf checked by the caller, gs_forward)
          rl_shade_tile_f32((const float*)acc.data(), Cf, (const float*)T.data(), TILE, ox, oy, ex, ey, W,
                            out.ptr[0], shade_prm, shade_flags);
      for (int y = oy; y <= ey; ++y)
        for (int j = 0; j < NJ && ox + j * L <= ex; ++j) {
          const int v = (y - oy) * NJ + j, nl = std::min(L, ex - (ox + j * L) + 1);
          const int64_t p = (int64_t)y * W + ox + j * L;
          for (int q = 0; q < (GROUPS ? NG : 0); ++q)
            store_lanes(A_grp + (int64_t)q * H * W + p, (S)1 - TG[(size_t)q * NV + v], nl);
          if (T_final) store_lanes(T_final + p, T[v], nl);
          store_lanes(alpha + p, (S)1 - T[v], nl);
          if (!last) {
          } else if (sizeof(IS) == 4) {
            store_lanes(last + p, lst[v], nl);
          } else {
            for (int l = 0; l < nl; ++l) last[p + l] = (int32_t)lst[v][l];
          }
          const V* a = acc.data() + (size_t)v * Cf;
          for (int q = 0, c0 = 0; q < out.n; c0 += out.size[q++]) {  // pixel-major per plane
            const int cq = out.size[q];
            if (!out.ptr[q] || (q == 0 && shade_prm)) continue;  // not wanted, or shaded above
            S* __restrict const o = out.ptr[q] + p * cq;
            if (q == 0 && bg) {  // over the background: c + T_final bg (as rgb + T_final * bg in torch)
              for (int l = 0; l < nl; ++l)
                for (int c = 0; c < cq; ++c) o[l * cq + c] = a[c][l] + T[v][l] * bg[c];
              continue;
            }
            if (cq == 1) {  // one channel (depth): the lanes are the pixels
              store_lanes(o, a[c0], nl);
              continue;
            }
            for (int l = 0; l < nl; ++l)
              for (int c = 0; c < cq; ++c) o[l * cq + c] = a[c0 + c][l];
          }
        }
    }
  }
}

// Several cameras of one size in one parallel region (no backward: a render for a dataset, a
// preview, a figure): threads over camera x Gaussian block (records, and each camera's depth sort
// as one more item, so the serial sorts of two cameras run side by side), camera x chunk (tile
// counts, then the tile lists), and camera x tile (blending, camera by camera, the busiest tiles
// of each first). Each camera's image comes from the same steps as forward() after bin(): the same
// records, depth order, tile lists and tile blending (blend_tile), so it is bit-identical to a
// render of that camera alone. Five barriers for all cameras where bin() and forward() take two
// each and two ends of parallel regions, per camera.
// means2d, conics, opac, depths, radii, boxes: camera-major (C, N, ...). in: NI parts of the
// channels, part i read at in.ptr[i] + c * in_stride[i] for camera c (stride 0: shared by every
// camera, e.g. instance one-hots; N * size: per camera, e.g. the SH colour and the depth).
// out: the planes of every camera, plane q of camera c at out.ptr[q] + c * H * W * out.size[q]
// (null: not written); alpha (C, H, W); bg: (C, out.size[0]) or null.
template <typename S, int CF>
void forward_cameras(int C, int64_t N, const S* means2d, const S* conics, const S* opac, const S* depths,
                     const int64_t* radii, const int64_t* boxes, int W, int H, int nt, Planes<const S*> in,
                     const int64_t* in_stride, int Cf_, Planes<S*> out, S* alpha, const S* bg) {
  const int Cf = CF > 0 ? CF : Cf_;
  const int TX = (W + TILE - 1) / TILE, TY = (H + TILE - 1) / TILE, NT = TX * TY;
  const int NC = n_chunks(nt);
  const int64_t NB = (N + GAUSS_BLOCK - 1) / GAUSS_BLOCK, HW = (int64_t)H * W;
  typedef decltype(fkey(S())) K;
  // scratch reused across calls (the calling thread's; the OpenMP threads use plain pointers)
  static thread_local std::vector<Rec<S>> rec_buf, by_index_buf;
  static thread_local std::vector<K> key_buf;
  static thread_local std::vector<int32_t> idx_buf, order_buf, list_buf;
  static thread_local std::vector<int64_t> cursor_buf, toff_buf;
  static thread_local std::vector<S> feat_buf;
  const int64_t CN = (int64_t)C * N;
  if ((int64_t)rec_buf.size() < CN) {
    rec_buf.resize(CN), by_index_buf.resize(CN), key_buf.resize(2 * CN), idx_buf.resize(2 * CN);
    order_buf.resize(CN);
  }
  if ((int64_t)feat_buf.size() < CN * Cf) feat_buf.resize(CN * Cf);
  cursor_buf.assign((size_t)C * NC * NT, 0);
  toff_buf.resize((size_t)C * (NT + 1));
  Rec<S>* const recs = rec_buf.data();
  Rec<S>* const by_index = by_index_buf.data();
  K* const key = key_buf.data();
  int32_t* const idx = idx_buf.data();
  int32_t* const order = order_buf.data();
  int64_t* const cursor = cursor_buf.data();
  int64_t* const tile_off = toff_buf.data();
  S* const feats = feat_buf.data();
  std::vector<int64_t> nv(C, 0), list_off(C + 1, 0);
  std::vector<const S*> in_ptr((size_t)C * in.n);
  std::vector<S*> out_ptr((size_t)C * out.n);
  for (int c = 0; c < C; ++c) {
    for (int i = 0; i < in.n; ++i) in_ptr[(size_t)c * in.n + i] = in.ptr[i] + c * in_stride[i];
    for (int q = 0; q < out.n; ++q) out_ptr[(size_t)c * out.n + q] = out.ptr[q] ? out.ptr[q] + c * HW * out.size[q] : nullptr;
  }
  int32_t* list = nullptr;
  // camera * NT + tile: camera by camera (its records stay in cache: at one thread 2-4 % less
  // time than the busiest tiles of all cameras first, at two the same), each busiest first (the
  // tail is the last camera's shortest tiles)
  std::vector<int64_t> torder;
#pragma omp parallel num_threads(nt)
  {
    // 1. records (index order) and, as the first C items, each camera's depth sort
#pragma omp for schedule(dynamic, 1)
    for (int64_t it = 0; it < C + C * NB; ++it) {
      if (it < C) {
        const int64_t c = it, o = c * N;
        K* const kc = key + 2 * o;
        int32_t* const ic = idx + 2 * o;
        int64_t m = 0;
        for (int64_t i = 0; i < N; ++i)
          if (radii[o + i] > 0) {
            kc[m] = fkey(depths[o + i]);
            ic[m++] = (int32_t)i;
          }
        radix_sort(m, kc, ic, kc + N, ic + N);
        std::copy_n(ic, m, order + o);
        nv[c] = m;
        continue;
      }
      const int64_t c = (it - C) / NB, b = (it - C) % NB * GAUSS_BLOCK, e = std::min(b + GAUSS_BLOCK, N);
      const int64_t o = c * N;
      for (int64_t i = b; i < e; ++i)
        make_rec(by_index[o + i], i, means2d + 2 * o, conics + 3 * o, opac + o, radii + o, boxes + 4 * o, W, H);
    }
    // 2. records gathered into depth order, tile counts per (camera, chunk)
#pragma omp for schedule(dynamic, 1)
    for (int it = 0; it < C * NC; ++it) {
      const int c = it / NC;
      const int64_t o = (int64_t)c * N;
      int64_t b, e;
      chunk(nv[c], NC, it % NC, b, e);
      int64_t* const cnt = cursor + (int64_t)it * NT;
      for (int64_t s = b; s < e; ++s) {
        if (s + 16 < e) __builtin_prefetch(by_index + o + order[o + s + 16]);
        const Rec<S>& r = recs[o + s] = by_index[o + order[o + s]];
        if (r.u1 < r.u0 || r.v1 < r.v0) continue;
        const int tx0 = r.u0 / TILE, tx1 = r.u1 / TILE, ty0 = r.v0 / TILE, ty1 = r.v1 / TILE;
        for (int ty = ty0; ty <= ty1; ++ty)
          for (int tx = tx0; tx <= tx1; ++tx) cnt[ty * TX + tx]++;
      }
    }
    // 3. per camera: tile offsets, each chunk's first write position per tile
#pragma omp for schedule(dynamic, 1)
    for (int c = 0; c < C; ++c) {
      int64_t* const to = tile_off + (int64_t)c * (NT + 1);
      int64_t* const cu = cursor + (int64_t)c * NC * NT;
      int64_t pos = 0;
      for (int t = 0; t < NT; ++t) {
        to[t] = pos;
        for (int ch = 0; ch < NC; ++ch) {
          const int64_t n = cu[(int64_t)ch * NT + t];
          cu[(int64_t)ch * NT + t] = pos;
          pos += n;
        }
      }
      to[NT] = pos;
    }
    // 4. the calling thread (its thread_local list buffer): list storage, the tiles' order
#pragma omp master
    {
      for (int c = 0; c < C; ++c) list_off[c + 1] = list_off[c] + tile_off[(int64_t)c * (NT + 1) + NT];
      if ((int64_t)list_buf.size() < std::max<int64_t>(list_off[C], 1)) list_buf.resize(std::max<int64_t>(list_off[C], 1));
      list = list_buf.data();
      torder.clear();
      for (int c = 0; c < C; ++c)
        for (int t : busiest_first(tile_off + (int64_t)c * (NT + 1), NT)) torder.push_back((int64_t)c * NT + t);
    }
#pragma omp barrier
    // 5. tile lists filled in depth order, channels gathered into depth order
#pragma omp for schedule(dynamic, 1)
    for (int it = 0; it < C * NC; ++it) {
      const int c = it / NC;
      const int64_t o = (int64_t)c * N;
      int64_t b, e;
      chunk(nv[c], NC, it % NC, b, e);
      int64_t* const cur = cursor + (int64_t)it * NT;
      int32_t* const lc = list + list_off[c];
      const S* const* ip = in_ptr.data() + (size_t)c * in.n;
      for (int64_t s = b; s < e; ++s) {
        const int64_t gi = order[o + s], gn = s + 16 < e ? order[o + s + 16] : gi;
        for (int q = 0, c0 = 0; q < in.n; c0 += in.size[q++]) {
          const int cq = in.size[q];
          __builtin_prefetch(ip[q] + gn * cq);
          const S* src = ip[q] + gi * cq;
          S* dst = feats + (o + s) * Cf + c0;
          for (int k = 0; k < cq; ++k) dst[k] = src[k];
        }
        const Rec<S>& r = recs[o + s];
        if (r.u1 < r.u0 || r.v1 < r.v0) continue;
        for (int ty = r.v0 / TILE; ty <= r.v1 / TILE; ++ty)
          for (int tx = r.u0 / TILE; tx <= r.u1 / TILE; ++tx) lc[cur[ty * TX + tx]++] = (int32_t)s;
      }
    }
    // 6. blending, camera x tile
    BlendScratch<S> sc(Cf, 0);
#pragma omp for schedule(dynamic, 1) nowait  // the region's end is the barrier
    for (int64_t it = 0; it < (int64_t)C * NT; ++it) {
      const int c = (int)(torder[it] / NT), t = (int)(torder[it] % NT);
      const int64_t* to = tile_off + (int64_t)c * (NT + 1);
      const Planes<S*> oc{out.n, out.size, out_ptr.data() + (size_t)c * out.n};
      blend_tile<S, false, CF>(t, TX, W, H, Cf, recs + (int64_t)c * N, list + list_off[c] + to[t], to[t + 1] - to[t],
                               feats + (int64_t)c * N * Cf, oc, nullptr, alpha + c * HW, nullptr, 0, nullptr,
                               nullptr, bg ? bg + (int64_t)c * out.size[0] : nullptr, nullptr, 0, sc);
    }
  }
}

// Backward: per tile, back to front from each pixel's last contributor, recovering T_k by
// dividing by (1 - alpha_k) (alpha <= 0.99). Per (tile, Gaussian) entry the sums over the tile's
// pixels go to gbuf, at the entry's slot in Gaussian-major order (slot, from the fill); then per
// Gaussian its contiguous slots are summed in a fixed order (deterministic, no atomics) and turned into gradients of means2d, conics, opacity and the Cf channels.
// g_out: dL/d out, as the forward's Planes (a null plane: no gradient); g_T, g_alpha (H x W):
// dL/d T_final and dL/d alpha, each or both null. Gradient arrays are indexed like the inputs
// (N of them, rank: bin's inverse of the depth order) and written whole: zero for the Gaussians
// that are not visible, so the caller allocates them uninitialised. g_feats: the input Planes'
// gradients (a null plane: not wanted). bg: the forward's background under plane 0 (or null);
// g_bg (plane 0's channel count): its gradient, sum over pixels of T_final dL/d out_0, summed per
// tile and then over tiles in tile order (the same bits for any thread count), or null.
template <typename S>
void backward(int64_t N, int64_t nv, const int32_t* order, const int32_t* rank, int Cf, int W, int H, int nt, const Rec<S>* recs,
              const int64_t* tile_off, const int64_t* goff, const int32_t* list, const int64_t* slot,
              const S* feats, const S* T_final, const int32_t* last, Planes<const S*> g_out, const S* g_T,
              const S* g_alpha, S* g_means2d, S* g_conics, S* g_opac, Planes<S*> g_feats, const S* bg,
              S* g_bg) {
  const int TX = (W + TILE - 1) / TILE, TY = (H + TILE - 1) / TILE, NT = TX * TY;
  const std::vector<int> torder = busiest_first(tile_off, NT);
  const int NB = 6 + Cf;  // q, q dx, q dy, q dx dx, q dx dy, q dy dy, w g_c
  const int64_t total = tile_off[NT];
  // reused across calls (no page faults per frame); used through a plain pointer (thread_local
  // is the calling thread's, not the OpenMP threads')
  static thread_local std::vector<S> gbuf_vec;
  if (gbuf_vec.size() < (size_t)total * NB) gbuf_vec.resize((size_t)total * NB);
  S* const gbuf = gbuf_vec.data();
  const int C0 = g_out.size[0];
  const S* const g0 = g_out.ptr[0];
  const bool want_bg = bg && g_bg && g0;
  std::vector<double> bg_part(want_bg ? (size_t)NT * C0 : 0);  // per tile: sum of T_final dL/d out_0
#pragma omp parallel num_threads(nt)
  {
    typedef typename VT<S>::V V;
    typedef typename VT<S>::I I;
    typedef typename std::remove_reference<decltype(I{}[0])>::type IS;
    constexpr int L = VT<S>::L, NV = TPIX / L, NJ = TILE / L;
    const std::vector<V> lane_xc = Entry<S>::lane_centres();
    std::vector<V> T(NV), accum(NV), G((size_t)NV * Cf), sums((NB + 7) / 8 * 8);
    std::vector<I> lst(NV);
#pragma omp for schedule(dynamic, 1)
    for (int it = 0; it < NT; ++it) {
      const int t = torder[it];
      const auto [ox, oy, ex, ey] = TileRect(t, TX, W, H);
      const int64_t t0 = tile_off[t];
      if (want_bg)
        for (int c = 0; c < C0; ++c) {
          double h = 0;
          for (int y = oy; y <= ey; ++y)
            for (int x = ox; x <= ex; ++x) {
              const int64_t p = (int64_t)y * W + x;
              h += (double)g0[p * C0 + c] * (double)T_final[p];
            }
          bg_part[(size_t)t * C0 + c] = h;
        }
      if (tile_off[t + 1] == t0) continue;  // most tiles of a bike image are empty
      int kmax = 0;
      std::fill(T.begin(), T.end(), (V){} + (S)1);
      std::fill(accum.begin(), accum.end(), (V){});
      std::fill(G.begin(), G.end(), (V){});
      std::fill(lst.begin(), lst.end(), (I){});
      for (int y = oy; y <= ey; ++y)
        for (int j = 0; j < NJ && ox + j * L <= ex; ++j) {
          const int v = (y - oy) * NJ + j, nl = std::min(L, ex - (ox + j * L) + 1);
          const int64_t p = (int64_t)y * W + ox + j * L;
          for (int l = 0; l < nl; ++l) {
            T[v][l] = T_final[p + l];
            lst[v][l] = last[p + l];
            kmax = std::max(kmax, (int)last[p + l]);
            // behind: S_k + T_final dL/dT_final (alpha = 1 - T_final; out_0 + T_final bg)
            S gt = (g_T ? g_T[p + l] : (S)0) - (g_alpha ? g_alpha[p + l] : (S)0);
            if (bg && g0)
              for (int c = 0; c < C0; ++c) gt += g0[(p + l) * C0 + c] * bg[c];
            accum[v][l] = T_final[p + l] * gt;
          }
          for (int l = 0; l < nl; ++l)
            for (int q = 0, c0 = 0; q < g_out.n; c0 += g_out.size[q++]) {
              const int cq = g_out.size[q];
              const S* const go = g_out.ptr[q];
              for (int c = 0; c < cq; ++c) G[(size_t)v * Cf + c0 + c][l] = go ? go[(p + l) * cq + c] : (S)0;
            }
        }
      for (int k = kmax - 1; k >= 0; --k) {
        if (k >= PF) {
          __builtin_prefetch(recs + list[t0 + k - PF]);
          __builtin_prefetch(feats + (int64_t)list[t0 + k - PF] * Cf);
        }
        const int32_t sp = list[t0 + k];
        const Rec<S>& g = recs[sp];
        const S* f = feats + (int64_t)sp * Cf;
        std::fill(sums.begin(), sums.end(), (V){});
        const Entry<S> en(g, ox, oy, ex, ey, lane_xc.data());
        const I kk = (I){} + (IS)k;
        for (int y = en.y0; y <= en.y1; ++y) {
          V by, cyy;
          const S dy = Entry<S>::row(g, y, by, cyy);
          // sums over the row of q, q dx, q dx^2; the dy factors are applied once per row
          V rq = (V){}, rqx = (V){}, rqxx = (V){};
          for (int j = en.j0; j <= en.j1; ++j) {
            const int v = (y - oy) * NJ + j;
            const I live = en.box[j] & (kk < lst[v]);
            if (!any(live)) continue;
            const V sigma = en.sigma(j, by, cyy);
            const I pre = live & (sigma <= g.tau);
            if (!any(pre)) continue;
            const V ar = Entry<S>::alpha_raw(g, sigma);
            const I m = pre & (ar >= (S)ALPHA_MIN);
            if (!any(m)) continue;
            const V al = ar < (S)ALPHA_MAX ? ar : (V){} + (S)ALPHA_MAX;
            const V rom = (S)1 / ((S)1 - al);
            const V Tk = T[v] * rom;  // the transmittance in front of this Gaussian
            T[v] = m ? Tk : T[v];
            const V w = m ? al * Tk : (V){};
            const V* gp = G.data() + (size_t)v * Cf;
            V vv = (V){};
            for (int c = 0; c < Cf; ++c) {
              vv = vfma(gp[c], (V){} + f[c], vv);
              sums[6 + c] = vfma(w, gp[c], sums[6 + c]);
            }
            const V g_alpha = Tk * vv - accum[v] * rom;
            accum[v] = vfma(w, vv, accum[v]);
            // no gradient through the 0.99 clamp; q = -dL/dsigma
            const V q = (m & (ar < (S)ALPHA_MAX)) ? g_alpha * ar : (V){};
            const V qx = q * en.dx[j];
            rq += q;
            rqx += qx;
            rqxx = vfma(qx, en.dx[j], rqxx);
          }
          sums[0] += rq;
          sums[1] += rqx;
          sums[2] = vfma(rq, (V){} + dy, sums[2]);
          sums[3] += rqxx;
          sums[4] = vfma(rqx, (V){} + dy, sums[4]);
          sums[5] = vfma(rq, (V){} + dy * dy, sums[5]);
        }
        hsum(sums.data(), NB, gbuf + (size_t)slot[t0 + k] * NB);
      }
      // entries past every pixel's last contributor got nothing: zero them
      const int64_t n = tile_off[t + 1] - t0;
      for (int64_t k = kmax; k < n; ++k) std::fill_n(gbuf + (size_t)slot[t0 + k] * NB, NB, (S)0);
    }
    if (want_bg) {
#pragma omp single nowait  // while the others start on the per-Gaussian sums
      for (int c = 0; c < C0; ++c) {
        double h = 0;
        for (int t = 0; t < NT; ++t) h += bg_part[(size_t)t * C0 + c];
        g_bg[c] = (S)h;
      }
    }
    // the Gaussians that are not visible: zeros (the caller's buffers are uninitialised)
#pragma omp for schedule(dynamic, GAUSS_BLOCK) nowait
    for (int64_t gi = 0; gi < N; ++gi) {
      if (rank[gi] >= 0) continue;
      g_means2d[2 * gi] = g_means2d[2 * gi + 1] = 0;
      g_conics[3 * gi] = g_conics[3 * gi + 1] = g_conics[3 * gi + 2] = 0;
      g_opac[gi] = 0;
      for (int q = 0; q < g_feats.n; ++q)
        if (g_feats.ptr[q]) std::fill_n(g_feats.ptr[q] + gi * g_feats.size[q], g_feats.size[q], (S)0);
    }
    std::vector<S> accv(NB);
    // the visible ones in depth order: their slots and records are read sequentially (in index
    // order those reads were random: +0.5 ms at one thread, measured)
#pragma omp for schedule(dynamic, GAUSS_BLOCK) nowait  // the region's end is the barrier
    for (int64_t s = 0; s < nv; ++s) {
      const int64_t gi = order[s];
      // summed locally, written once (read-modify-write of the output stalled on store forwarding)
      S* acc = accv.data();
      const S* e0 = gbuf + (size_t)goff[s] * NB;
      const int64_t ne = goff[s + 1] - goff[s];  // this Gaussian's entries: contiguous
      for (int j = 0; j < NB; ++j) {  // a register sum per quantity (no store-to-load round trips)
        S h = 0;
        for (int64_t k = 0; k < ne; ++k) h += e0[k * NB + j];
        acc[j] = h;
      }
      for (int q = 0, c0 = 0; q < g_feats.n; c0 += g_feats.size[q++])
        if (g_feats.ptr[q]) std::copy_n(acc + 6 + c0, g_feats.size[q], g_feats.ptr[q] + gi * g_feats.size[q]);
      const Rec<S>& g = recs[s];
      g_means2d[2 * gi] = g.a * acc[1] + g.b * acc[2];
      g_means2d[2 * gi + 1] = g.b * acc[1] + g.c * acc[2];
      g_conics[3 * gi] = (S)-0.5 * acc[3];
      g_conics[3 * gi + 1] = -acc[4];
      g_conics[3 * gi + 2] = (S)-0.5 * acc[5];
      g_opac[gi] = acc[0] / std::max(g.o, (S)1e-30);
    }
  }
}

}  // namespace

extern "C" {

int gs_tile_size() { return TILE; }
int gs_chunks(int nt) { return n_chunks(nt); }
int gs_rec_bytes_f32() { return (int)sizeof(Rec<float>); }
int gs_rec_bytes_f64() { return (int)sizeof(Rec<double>); }

#define GS_EXPORT(SUFFIX, S)                                                                       \
  void gs_bin_##SUFFIX(int64_t N, const S* means2d, const S* conics, const S* opac,                \
                       const S* depths, const int64_t* radii, const int64_t* boxes, int W, int H,  \
                       int nt, void* recs, int32_t* order, int32_t* rank, int64_t* cursor,        \
                       int64_t* tile_off, int64_t* goff, int64_t* sizes) {                         \
    bin<S>(N, means2d, conics, opac, depths, radii, boxes, W, H, nt, (Rec<S>*)recs, order, rank,   \
           cursor, tile_off, goff, sizes);                                                         \
  }                                                                                                \
  /* shade_prm, shade_flags: forward<>'s relit tile epilogue (float, no groups, no background, */   \
  /* plane 0 of 3 channels, Cf as the flags need; else -1 and nothing is done). Returns 0. */      \
  int gs_forward_##SUFFIX(int64_t nv, const int32_t* order, int NI, const int* isz,               \
                          const S* const* feats, int Cf, int W,                                   \
                          int H, int nt, const void* recs, int64_t* cursor, const int64_t* tile_off, \
                          const int64_t* goff, int32_t* list, int64_t* slot, S* feats_sorted,     \
                          int NO, const int* osz, S* const* outs, S* T_final, S* alpha,           \
                          int32_t* last, const int32_t* grp_in, int NG, int32_t* grp, S* A_grp,   \
                          const S* bg, const float* shade_prm, int32_t shade_flags) {             \
    if (shade_prm && (sizeof(S) != sizeof(float) || NG > 0 || bg || NO < 1 || osz[0] != 3 || !outs[0] || \
                      Cf != rl_shade_tile_channels(shade_flags)))                                  \
      return -1;                                                                                   \
    const Planes<S*> out{NO, osz, outs};                                                           \
    /* the inputs: parts of the planes (several parts may fill one plane), per Gaussian */        \
    const Planes<const S*> in{NI, isz, feats};                                                     \
    const Rec<S>* r = (const Rec<S>*)recs;                                                         \
    const float* sp = shade_prm;                                                                   \
    const int32_t sf = shade_flags;                                                                \
    if (NG > 0)                                                                                    \
      forward<S, true, 0>(nv, order, in, Cf, W, H, nt, r, cursor, tile_off, goff, list, slot,       \
                          feats_sorted, out, T_final, alpha, last, grp_in, NG, grp, A_grp, bg, sp, sf); \
    else if (Cf == 4) /* colour + depth: a plain render */                                         \
      forward<S, false, 4>(nv, order, in, Cf, W, H, nt, r, cursor, tile_off, goff, list, slot,      \
                           feats_sorted, out, T_final, alpha, last, nullptr, 0, nullptr, nullptr, bg, sp, sf); \
    else if (Cf == 7) /* colour + relight features (splatting/relight/render.py) */                \
      forward<S, false, 7>(nv, order, in, Cf, W, H, nt, r, cursor, tile_off, goff, list, slot,      \
                           feats_sorted, out, T_final, alpha, last, nullptr, 0, nullptr, nullptr, bg, sp, sf); \
    else if (Cf == 8) /* colour + relight features + sky visibility (a bike's, RelightableBike) */ \
      forward<S, false, 8>(nv, order, in, Cf, W, H, nt, r, cursor, tile_off, goff, list, slot,      \
                           feats_sorted, out, T_final, alpha, last, nullptr, 0, nullptr, nullptr, bg, sp, sf); \
    else                                                                                           \
      forward<S, false, 0>(nv, order, in, Cf, W, H, nt, r, cursor, tile_off, goff, list, slot,      \
                           feats_sorted, out, T_final, alpha, last, nullptr, 0, nullptr, nullptr, bg, sp, sf); \
    return 0;                                                                                      \
  }                                                                                                \
  void gs_backward_##SUFFIX(int64_t N, int64_t nv, const int32_t* order, const int32_t* rank,      \
                            int Cf, int W, int H,                                                  \
                            int nt, const void* recs, const int64_t* tile_off, const int64_t* goff, \
                            const int32_t* list, const int64_t* slot, const S* feats,              \
                            const S* T_final, const int32_t* last, int NO, const int* osz,         \
                            const S* const* g_outs, const S* g_T, const S* g_alpha, S* g_means2d,  \
                            S* g_conics, S* g_opac, S* const* g_feats, const S* bg, S* g_bg) {     \
    backward<S>(N, nv, order, rank, Cf, W, H, nt, (const Rec<S>*)recs, tile_off, goff, list, slot, feats, \
                T_final, last, Planes<const S*>{NO, osz, g_outs}, g_T, g_alpha, g_means2d,         \
                g_conics, g_opac, Planes<S*>{NO, osz, g_feats}, bg, g_bg);                         \
  }

GS_EXPORT(f32, float)
GS_EXPORT(f64, double)

// forward_cameras (no backward): C cameras of one size; see there for the layouts. NI input
// parts (isz channels each, camera stride in_stride), NO output planes (osz channels each).
#define GS_CAMS_EXPORT(SUFFIX, S)                                                                   \
  void gs_forward_cameras_##SUFFIX(int C, int64_t N, const S* means2d, const S* conics, const S* opac, \
                                   const S* depths, const int64_t* radii, const int64_t* boxes, int W, \
                                   int H, int nt, int NI, const int* isz, const S* const* feats,       \
                                   const int64_t* in_stride, int Cf, int NO, const int* osz,           \
                                   S* const* outs, S* alpha, const S* bg) {                            \
    const Planes<const S*> in{NI, isz, feats};                                                     \
    const Planes<S*> out{NO, osz, outs};                                                           \
    if (Cf == 4) /* colour + depth: a plain render */                                              \
      forward_cameras<S, 4>(C, N, means2d, conics, opac, depths, radii, boxes, W, H, nt, in, in_stride, Cf, out, \
                            alpha, bg);                                                            \
    else                                                                                           \
      forward_cameras<S, 0>(C, N, means2d, conics, opac, depths, radii, boxes, W, H, nt, in, in_stride, Cf, out, \
                            alpha, bg);                                                            \
  }

GS_CAMS_EXPORT(f32, float)
GS_CAMS_EXPORT(f64, double)

}  // extern "C"
