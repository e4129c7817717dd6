// Per-pixel relit shading of composited relight channels: the formula of
// splatting/relight/shading.py (_shade_cm), fused into one pass over the covered pixels, which
// otherwise costs ~80 small torch operations per render (most of relight_render_overhead).
// Serial (a few hundred thousand pixels at most): deterministic and no thread pool contention
// with the rasterizer's.  Two entry points share the per-pixel formula (shade_px):
//  - rl_shade_f32, over whole images (splatting/relight/render.py::shade_composited): per row the
//    covered pixels' channels gathered into contiguous per-channel buffers, then the formula SIMD
//    across them (8 pixels an instruction with AVX2);
//  - rl_shade_tile_f32, the compositor's tile epilogue (csrc/tiles.cpp, a relit render through
//    rasterize(shade=...)): the tile's blended channels shaded straight from its accumulators
//    (8 pixels of a row per vector, channel-major) before anything is written, so a relit render
//    writes its colour and alpha only, not the reflectance and feature images the shading would
//    read back (docs/relighting.md).
// Built into the rasterizer's library (splatting/raster/build.py SOURCES).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

namespace {
constexpr float kPi = 3.14159265358979323846f;
inline float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
// all 8 floats at p are +0.0 (their bits are)
inline bool blank8(const float* p) {
    uint64_t w[4];
    std::memcpy(w, p, sizeof(w));
    return (w[0] | w[1] | w[2] | w[3]) == 0;
}
// x^(1/2.4) for x in [0.0031308, 1] (the sRGB curve's power segment) as exp(ln(x) / 2.4), with
// Cephes' logf and expf polynomials (the latter as tiles.cpp's vexp): plain float arithmetic and
// bit moves that vectorise inside the pixel loops.  Measured over every float of that range:
// at most 5.1e-7 relative error, and srgb() at most 1.6e-7 from the double-precision curve.
// Hand-written because glibc's vectorised powf (a general x^y) was most of the shading's time:
// relit 512 px views 0.14-0.27 ms faster with this (docs/relighting.md).
inline float pow_inv24(float x) {
    uint32_t u = __builtin_bit_cast(uint32_t, x);
    int e = int(u >> 23) - 126;                                        // x = m 2^e, m in [0.5, 1)
    float m = __builtin_bit_cast(float, (u & 0x007fffffu) | 0x3f000000u);
    if (m < 0.70710678f) {                                             // m in [sqrt(1/2), sqrt(2))
        e -= 1;
        m = m + m - 1.0f;
    } else {
        m = m - 1.0f;
    }
    const float z = m * m;
    float p = 7.0376836292e-2f;
    p = p * m - 1.1514610310e-1f;
    p = p * m + 1.1676998740e-1f;
    p = p * m - 1.2420140846e-1f;
    p = p * m + 1.4249322787e-1f;
    p = p * m - 1.6668057665e-1f;
    p = p * m + 2.0000714765e-1f;
    p = p * m - 2.4999993993e-1f;
    p = p * m + 3.3333331174e-1f;
    const float fe = float(e);
    float ln = m + (p * m * z - 2.12194440e-4f * fe - 0.5f * z);
    ln += 0.693359375f * fe;                                            // ln(x), in [-5.8, 0]
    const float y = ln * (1.0f / 2.4f);                                 // in [-2.5, 0]
    const float fn = std::floor(y * 1.44269504088896341f + 0.5f);       // y = n ln2 + r
    float r = y - fn * 0.693359375f;
    r = r + fn * 2.12194440e-4f;
    float q = 1.9875691500e-4f;
    q = q * r + 1.3981999507e-3f;
    q = q * r + 8.3334519073e-3f;
    q = q * r + 4.1665795894e-2f;
    q = q * r + 1.6666665459e-1f;
    q = q * r + 5.0000001201e-1f;
    q = q * (r * r) + r + 1.0f;
    return q * __builtin_bit_cast(float, uint32_t(int(fn) + 127) << 23);
}
inline float srgb(float x) {
    x = clampf(x, 0.0f, 1.0f);
    return x <= 0.0031308f ? 12.92f * x : 1.055f * pow_inv24(x > 0.0031308f ? x : 0.0031308f) - 0.055f;
}

// prm and flags (see rl_shade_f32) unpacked into scalars: loads from prm inside the pixel loop
// kept gcc from vectorising it
struct Prm {
    float l0, l1, l2, sun0, sun1, sun2, sky0, sky1, sky2, fx, fy, cx, cy, Rc[9], rough0, highlight;
    bool gloss, rough_ch, shadows, in_place, sky_ch;
    int c_rough, c_vis, c_sky;  // the optional channels' places among the features
    Prm(const float* prm, int32_t flags) {
        l0 = prm[0], l1 = prm[1], l2 = prm[2];
        sun0 = prm[3], sun1 = prm[4], sun2 = prm[5], sky0 = prm[6], sky1 = prm[7], sky2 = prm[8];
        fx = prm[9], fy = prm[10], cx = prm[11], cy = prm[12];
        for (int k = 0; k < 9; ++k) Rc[k] = prm[13 + k];
        rough0 = prm[22], highlight = prm[23];
        gloss = flags & 1, rough_ch = flags & 2, shadows = flags & 4, in_place = flags & 8, sky_ch = flags & 16;
        c_rough = 3 + gloss, c_vis = 3 + gloss + rough_ch, c_sky = c_vis + shadows;
    }
    int channels() const { return 3 + gloss + rough_ch + shadows + sky_ch; }
};

// One pixel's straight colour, clamped to [0, 1], before the sRGB encoding: alpha a (> 1e-5),
// premultiplied reflectance r, composited normal n, gloss luminance, roughness, sun and sky
// visibility (premultiplied; read only when their flag is set), x the pixel column's view ray
// part ((u + 0.5 - cx) / fx), vy its row's (y Rc[3 + j] + Rc[6 + j]).  Inlined into SIMD loops;
// the flags are template arguments (with_flags): as run-time bools gcc 12 vectorised the loop
// only while the formula was written out inside it.
template <bool gloss, bool rough_ch, bool shadows, bool sky_ch>
__attribute__((always_inline)) inline void shade_px(const Prm& P, float a, float r0, float r1, float r2, float n0,
                                                    float n1, float n2, float lum_c, float rough_c, float vis_c,
                                                    float sky_c, float x, float vy0, float vy1, float vy2, float& o0,
                                                    float& o1, float& o2) {
    const float ac = a > 1e-6f ? a : 1e-6f;
    float g0 = 0.0f, g1 = 0.0f, g2 = 0.0f;  // the gloss colour, the rest is albedo
    if constexpr (gloss) {
        // per pixel the gloss colour is the reflectance's tint times the composited gloss
        // luminance (exact for grey gloss: metals, clear coats)
        float lum = 0.2126f * r0 + 0.7152f * r1 + 0.0722f * r2;
        lum = lum > 1e-6f ? lum : 1e-6f;
        const float share = clampf(lum_c / lum, 0.0f, 1.0f);
        g0 = r0 * share, g1 = r1 * share, g2 = r2 * share;
    }
    const float a0 = r0 - g0, a1 = r1 - g1, a2_ = r2 - g2;
    const float rough = rough_ch ? clampf(rough_c / ac, 0.05f, 1.0f) : P.rough0;
    const float vis = shadows ? clampf(vis_c / ac, 0.0f, 1.0f) : 1.0f;
    const float skv = sky_ch ? clampf(sky_c / ac, 0.0f, 1.0f) : 1.0f;  // the sky's share
    const float k0 = P.sky0 * skv, k1 = P.sky1 * skv, k2 = P.sky2 * skv;
    float nn = std::sqrt(n0 * n0 + n1 * n1 + n2 * n2);
    nn = nn > 1e-6f ? nn : 1e-6f;
    n0 /= nn, n1 /= nn, n2 /= nn;
    float cosl = n0 * P.l0 + n1 * P.l1 + n2 * P.l2;
    cosl = cosl > 0.0f ? cosl : 0.0f;
    const float k = cosl / kPi * vis;
    float s0 = (P.sun0 * k + k0) * a0, s1 = (P.sun1 * k + k1) * a1, s2 = (P.sun2 * k + k2) * a2_;
    if constexpr (gloss) {
        // the view direction: from the pixel's surface towards the camera, in the world
        float w0 = x * P.Rc[0] + vy0, w1 = x * P.Rc[1] + vy1, w2 = x * P.Rc[2] + vy2;
        const float vn = std::sqrt(w0 * w0 + w1 * w1 + w2 * w2);
        w0 = -w0 / vn, w1 = -w1 / vn, w2 = -w2 / vn;
        float h0 = w0 + P.l0, h1 = w1 + P.l1, h2 = w2 + P.l2;
        float hn = std::sqrt(h0 * h0 + h1 * h1 + h2 * h2);
        hn = hn > 1e-6f ? hn : 1e-6f;
        h0 /= hn, h1 /= hn, h2 /= hn;
        const float nh = clampf(n0 * h0 + n1 * h1 + n2 * h2, 0.0f, 1.0f);
        float nv = n0 * w0 + n1 * w1 + n2 * w2;
        nv = nv > 0.05f ? nv : 0.05f;  // grazing pixels: the lobe's 1/(n.v) would explode
        const float r4 = rough * rough * rough * rough;
        const float t = nh * nh * (r4 - 1.0f) + 1.0f;
        const float D = cosl > 0.0f ? r4 / (t * t * (4.0f * kPi) * nv) : 0.0f;
        const float spec = D * P.highlight * vis;
        s0 += (P.sun0 * spec + k0) * g0, s1 += (P.sun1 * spec + k1) * g1, s2 += (P.sun2 * spec + k2) * g2;
    }
    o0 = clampf(s0 / ac, 0.0f, 1.0f), o1 = clampf(s1 / ac, 0.0f, 1.0f), o2 = clampf(s2 / ac, 0.0f, 1.0f);
}

// f(G, R, S, K) with the flags as std::integral_constant<bool, ...> (shade_px's template arguments)
template <class F>
inline void with_flags(const Prm& P, F&& f) {
    auto pick = [](bool x, auto&& next) {
        if (x)
            next(std::true_type{});
        else
            next(std::false_type{});
    };
    pick(P.gloss, [&](auto G) {
        pick(P.rough_ch, [&](auto R) { pick(P.shadows, [&](auto S) { pick(P.sky_ch, [&](auto K) { f(G, R, S, K); }); }); });
    });
}
}  // namespace

// The pixels of rows v0..v1-1, columns u0..u1-1 of a W-wide image whose alpha exceeds 1e-5; the
// box's others are set to 0 (so a caller shading the whole image needs no zero-filled output: one
// pass instead of two over it), pixels outside the box are left as they are.  R: reflectance (albedo + gloss), pixel stride sR, channels
// contiguous; F: relight features (normal 3, [gloss luminance], [roughness], [visibility], [sky visibility]), pixel
// stride sF; A: alpha (contiguous).  out: (H W, 3).  prm: l[3] (unit, towards the sun), sun[3] (colour x strength), sky[3],
// fx, fy, cx, cy, Rc[9] (world-to-camera rotation, row-major), roughness, highlight.
// flags: 1 gloss, 2 per-pixel roughness channel, 4 sun visibility channel, 8 in place (out is R,
// pixel stride 3): pixels whose alpha is exactly 0 are left as they are (the compositor's R is 0
// there: no Gaussian reached them), so only covered pixels are written; 16 sky visibility channel
// (the share of the sky a surface sees: shadow.sky_visibility), scaling the sky for albedo and gloss.
extern "C" void rl_shade_f32(int64_t W, int64_t u0, int64_t v0, int64_t u1, int64_t v1, const float* R, int64_t sR,
                             const float* F, int64_t sF, const float* A, float* out, const float* prm, int32_t flags) {
    const Prm P(prm, flags);
    const bool gloss = P.gloss, rough_ch = P.rough_ch, shadows = P.shadows, in_place = P.in_place, sky_ch = P.sky_ch;
    const int c_rough = P.c_rough, c_vis = P.c_vis, c_sky = P.c_sky;
    const int64_t n = u1 > u0 ? u1 - u0 : 0;
    // per row, the covered pixels' inputs channel by channel (contiguous: the SIMD loop reads them
    // with plain vector loads), then their straight colours, then the sRGB encoding (powf: with
    // -ffast-math gcc calls glibc's SIMD powf)
    enum { kA, kR0, kR1, kR2, kN0, kN1, kN2, kLum, kRough, kVis, kSky, kX, kS0, kS1, kS2, kBufs };
    std::vector<float> buf(kBufs * n);
    float* b[kBufs];
    for (int k = 0; k < kBufs; ++k) b[k] = buf.data() + k * n;
    std::vector<int64_t> qbuf(n);
    for (int64_t q0 = v0 * W; q0 < v1 * W; q0 += W) {
        int64_t m = 0;
        for (int64_t q = q0 + u0; q < q0 + u1; ++q) {
            // runs of 8 pixels of alpha exactly 0 (most of an image: no Gaussian reached them)
            // at once: 4 integer loads instead of 8 compares and branches
            while (q + 8 <= q0 + u1 && blank8(A + q)) {
                if (!in_place) std::fill_n(out + 3 * q, 24, 0.0f);
                q += 8;
            }
            if (q >= q0 + u1) break;
            const float a = A[q];
            if (!(a > 1e-5f)) {  // uncovered: nothing to shade (the torch path's threshold)
                if (!in_place || a != 0.0f) out[3 * q] = out[3 * q + 1] = out[3 * q + 2] = 0.0f;
                continue;
            }
            const float* r = R + q * sR;
            const float* f = F + q * sF;
            b[kA][m] = a;
            b[kR0][m] = r[0], b[kR1][m] = r[1], b[kR2][m] = r[2];
            b[kN0][m] = f[0], b[kN1][m] = f[1], b[kN2][m] = f[2];
            b[kLum][m] = gloss ? f[3] : 0.0f;
            b[kRough][m] = rough_ch ? f[c_rough] : 0.0f;
            b[kVis][m] = shadows ? f[c_vis] : 0.0f;
            b[kSky][m] = sky_ch ? f[c_sky] : 0.0f;
            b[kX][m] = float(q - q0);
            qbuf[m++] = q;
        }
        const float y = (float(q0 / W) + 0.5f - P.cy) / P.fy;
        // the view direction's row part: y Rc[3 + j] + Rc[6 + j]
        const float vy0 = y * P.Rc[3] + P.Rc[6], vy1 = y * P.Rc[4] + P.Rc[7], vy2 = y * P.Rc[5] + P.Rc[8];
        const float *__restrict pA = b[kA], *__restrict pR0 = b[kR0], *__restrict pR1 = b[kR1],
                    *__restrict pR2 = b[kR2], *__restrict pN0 = b[kN0], *__restrict pN1 = b[kN1],
                    *__restrict pN2 = b[kN2], *__restrict pLum = b[kLum], *__restrict pRough = b[kRough],
                    *__restrict pVis = b[kVis], *__restrict pSky = b[kSky], *__restrict pX = b[kX];
        float *__restrict pS0 = b[kS0], *__restrict pS1 = b[kS1], *__restrict pS2 = b[kS2];
        with_flags(P, [&](auto G, auto RC, auto SH, auto SK) {
#pragma omp simd
            for (int64_t i = 0; i < m; ++i)  // a > 1e-5 here
                shade_px<G, RC, SH, SK>(P, pA[i], pR0[i], pR1[i], pR2[i], pN0[i], pN1[i], pN2[i], pLum[i], pRough[i],
                                        pVis[i], pSky[i], (pX[i] + 0.5f - P.cx) / P.fx, vy0, vy1, vy2, pS0[i], pS1[i],
                                        pS2[i]);
        });
#pragma omp simd
        for (int64_t i = 0; i < m; ++i) pS0[i] = srgb(pS0[i]), pS1[i] = srgb(pS1[i]), pS2[i] = srgb(pS2[i]);
        for (int64_t i = 0; i < m; ++i) {
            float* o = out + qbuf[i] * 3;
            const float a = b[kA][i];
            o[0] = b[kS0][i] * a, o[1] = b[kS1][i] * a, o[2] = b[kS2][i] * a;
        }
    }
}

// The compositor's tile epilogue (csrc/tiles.cpp forward, float32): one tile's pixels shaded
// straight from its accumulators and written to out (the display colour, (H W, 3) pixel-major,
// premultiplied; 0 where alpha <= 1e-5, as rl_shade_f32).  acc: the tile's composited channels,
// per 8-pixel vector v (row (v / (tile / 8)), columns 8 (v % (tile / 8)) ...) Cf channels of 8
// lanes each: the reflectance (3), then the relight features in rl_shade_f32's order and flags
// (flag 8 is ignored); T: the vectors' transmittance (alpha = 1 - T, the compositor's own
// expression); the tile covers columns ox..ex, rows oy..ey of a W-wide image.  Vectors with no
// covered pixel are only zero-filled; the others are shaded across all 8 lanes (one SIMD pass)
// and their uncovered lanes written as 0.  Returns -1 (writing nothing) when Cf is not the
// channel count the flags need, else 0.
extern "C" int rl_shade_tile_f32(const float* acc, int Cf, const float* T, int tile, int ox, int oy, int ex, int ey,
                                 int64_t W, float* out, const float* prm, int32_t flags) {
    constexpr int L = 8;
    const Prm P(prm, flags);
    if (Cf != 3 + P.channels() || tile % L) return -1;
    const bool gloss = P.gloss, rough_ch = P.rough_ch, shadows = P.shadows, sky_ch = P.sky_ch;
    // the optional channels' places in acc, channel 0 for those the flags leave out (read, unused:
    // unconditional loads vectorise, masked ones did not)
    const int NJ = tile / L, cg = gloss ? 6 : 0, cl = rough_ch ? 3 + P.c_rough : 0, cv = shadows ? 3 + P.c_vis : 0,
              cs = sky_ch ? 3 + P.c_sky : 0;
    for (int y = oy; y <= ey; ++y) {
        const float yr = (float(y) + 0.5f - P.cy) / P.fy;
        const float vy0 = yr * P.Rc[3] + P.Rc[6], vy1 = yr * P.Rc[4] + P.Rc[7], vy2 = yr * P.Rc[5] + P.Rc[8];
        for (int j = 0; j < NJ && ox + j * L <= ex; ++j) {
            const int v = (y - oy) * NJ + j, x0 = ox + j * L, nl = std::min(L, ex - x0 + 1);
            float* const o = out + ((int64_t)y * W + x0) * 3;
            const float* const Tv = T + (size_t)v * L;
            const float* const c = acc + (size_t)v * Cf * L;  // channel k's lane l: c[k L + l]
            float a[L];
            bool any = false;
            for (int l = 0; l < L; ++l) {
                a[l] = 1.0f - Tv[l];
                any |= a[l] > 1e-5f;
            }
            if (!any) {
                std::fill_n(o, 3 * nl, 0.0f);
                continue;
            }
            float s0[L], s1[L], s2[L];
            with_flags(P, [&](auto G, auto RC, auto SH, auto SK) {
#pragma omp simd
                for (int l = 0; l < L; ++l)
                    shade_px<G, RC, SH, SK>(P, a[l], c[l], c[L + l], c[2 * L + l], c[3 * L + l], c[4 * L + l],
                                            c[5 * L + l], c[cg * L + l], c[cl * L + l], c[cv * L + l], c[cs * L + l],
                                            (float(x0 + l) + 0.5f - P.cx) / P.fx, vy0, vy1, vy2, s0[l], s1[l], s2[l]);
            });
#pragma omp simd
            for (int l = 0; l < L; ++l) {
                const bool cov = a[l] > 1e-5f;
                s0[l] = cov ? srgb(s0[l]) * a[l] : 0.0f;
                s1[l] = cov ? srgb(s1[l]) * a[l] : 0.0f;
                s2[l] = cov ? srgb(s2[l]) * a[l] : 0.0f;
            }
            for (int l = 0; l < nl; ++l) o[3 * l] = s0[l], o[3 * l + 1] = s1[l], o[3 * l + 2] = s2[l];
        }
    }
    return 0;
}

// The channel count rl_shade_tile_f32 reads for these flags: reflectance 3 + the features.
extern "C" int rl_shade_tile_channels(int32_t flags) {
    return 3 + 3 + bool(flags & 1) + bool(flags & 2) + bool(flags & 4) + bool(flags & 16);
}

// View-dependent normals (splatting/relight/render.py view_normals, its no-grad float32 path):
// out_i = normalize(n_i + B_i v_i), v_i = normalize(c - mu_i) the unit direction from Gaussian i to
// the camera's centre c; n, mu, out (N, 3), B (N, 3, 3) row-major, all contiguous.  One pass over
// the Gaussians instead of ~10 torch operations (80k Gaussians: ~1.8 ms as torch operations).
extern "C" void rl_view_normals_f32(int64_t N, const float* n, const float* B, const float* mu, const float* c,
                                    float* out) {
    const float cx = c[0], cy = c[1], cz = c[2];
    for (int64_t i = 0; i < N; ++i) {
        float vx = cx - mu[3 * i], vy = cy - mu[3 * i + 1], vz = cz - mu[3 * i + 2];
        const float r = 1.0f / std::sqrt(std::max(vx * vx + vy * vy + vz * vz, 1e-24f));
        vx *= r; vy *= r; vz *= r;
        const float* b = B + 9 * i;
        const float ox = n[3 * i] + b[0] * vx + b[1] * vy + b[2] * vz;
        const float oy = n[3 * i + 1] + b[3] * vx + b[4] * vy + b[5] * vz;
        const float oz = n[3 * i + 2] + b[6] * vx + b[7] * vy + b[8] * vz;
        const float s = 1.0f / std::sqrt(std::max(ox * ox + oy * oy + oz * oz, 1e-12f));
        out[3 * i] = ox * s; out[3 * i + 1] = oy * s; out[3 * i + 2] = oz * s;
    }
}
