// Per-pixel relit shading of composited relight channels: the formula of
// splatting/relight/shading.py (_shade_cm), fused into one pass over the covered pixels, which
// otherwise costs ~80 small torch operations per render (most of relight_render_overhead).
// Serial (a few hundred thousand pixels at most): deterministic and no thread pool contention
// with the rasterizer's.  Per row: the covered pixels' channels gathered into contiguous
// per-channel buffers, then the formula SIMD across them (8 pixels an instruction with AVX2).  Built into the rasterizer's library
// (splatting/raster/build.py SOURCES); called from splatting/relight/render.py::shade_composited.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
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
inline float srgb(float x) {
    x = clampf(x, 0.0f, 1.0f);
    return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x > 1e-12f ? x : 1e-12f, 1.0f / 2.4f) - 0.055f;
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
    const float l0 = prm[0], l1 = prm[1], l2 = prm[2];
    const float* sun = prm + 3;
    const float* sky = prm + 6;
    const float fx = prm[9], fy = prm[10], cx = prm[11], cy = prm[12];
    const float* Rc = prm + 13;
    const float rough0 = prm[22], highlight = prm[23];
    // as scalars: loads from prm inside the pixel loop kept gcc from vectorising it
    const float sun0 = sun[0], sun1 = sun[1], sun2 = sun[2], sky0 = sky[0], sky1 = sky[1], sky2 = sky[2];
    const float Rc0 = Rc[0], Rc1 = Rc[1], Rc2 = Rc[2];
    const bool gloss = flags & 1, rough_ch = flags & 2, shadows = flags & 4, in_place = flags & 8,
               sky_ch = flags & 16;
    // the optional channels' places in F
    const int c_rough = 3 + gloss, c_vis = 3 + gloss + rough_ch, c_sky = c_vis + shadows;
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
        const float y = (float(q0 / W) + 0.5f - cy) / fy;
        // the view direction's row part: y Rc[3 + j] + Rc[6 + j]
        const float vy0 = y * Rc[3] + Rc[6], vy1 = y * Rc[4] + Rc[7], vy2 = y * Rc[5] + Rc[8];
        const float *__restrict pA = b[kA], *__restrict pR0 = b[kR0], *__restrict pR1 = b[kR1],
                    *__restrict pR2 = b[kR2], *__restrict pN0 = b[kN0], *__restrict pN1 = b[kN1],
                    *__restrict pN2 = b[kN2], *__restrict pLum = b[kLum], *__restrict pRough = b[kRough],
                    *__restrict pVis = b[kVis], *__restrict pSky = b[kSky], *__restrict pX = b[kX];
        float *__restrict pS0 = b[kS0], *__restrict pS1 = b[kS1], *__restrict pS2 = b[kS2];
#pragma omp simd
        for (int64_t i = 0; i < m; ++i) {
            const float a = pA[i];
            const float r0 = pR0[i], r1 = pR1[i], r2 = pR2[i];
            const float ac = a > 1e-6f ? a : 1e-6f;
            float g0 = 0.0f, g1 = 0.0f, g2 = 0.0f;  // the gloss colour, the rest is albedo
            if (gloss) {
                // per pixel the gloss colour is the reflectance's tint times the composited gloss
                // luminance (exact for grey gloss: metals, clear coats)
                float lum = 0.2126f * r0 + 0.7152f * r1 + 0.0722f * r2;
                lum = lum > 1e-6f ? lum : 1e-6f;
                const float share = clampf(pLum[i] / lum, 0.0f, 1.0f);
                g0 = r0 * share, g1 = r1 * share, g2 = r2 * share;
            }
            const float a0 = r0 - g0, a1 = r1 - g1, a2_ = r2 - g2;
            const float rough = rough_ch ? clampf(pRough[i] / ac, 0.05f, 1.0f) : rough0;
            const float vis = shadows ? clampf(pVis[i] / ac, 0.0f, 1.0f) : 1.0f;
            const float skv = sky_ch ? clampf(pSky[i] / ac, 0.0f, 1.0f) : 1.0f;  // the sky's share
            const float k0 = sky0 * skv, k1 = sky1 * skv, k2 = sky2 * skv;
            float n0 = pN0[i], n1 = pN1[i], n2 = pN2[i];
            float nn = std::sqrt(n0 * n0 + n1 * n1 + n2 * n2);
            nn = nn > 1e-6f ? nn : 1e-6f;
            n0 /= nn, n1 /= nn, n2 /= nn;
            float cosl = n0 * l0 + n1 * l1 + n2 * l2;
            cosl = cosl > 0.0f ? cosl : 0.0f;
            const float k = cosl / kPi * vis;
            float s0 = (sun0 * k + k0) * a0, s1 = (sun1 * k + k1) * a1, s2 = (sun2 * k + k2) * a2_;
            if (gloss) {
                // the view direction: from the pixel's surface towards the camera, in the world
                const float x = (pX[i] + 0.5f - cx) / fx;
                float w0 = x * Rc0 + vy0, w1 = x * Rc1 + vy1, w2 = x * Rc2 + vy2;
                const float vn = std::sqrt(w0 * w0 + w1 * w1 + w2 * w2);
                w0 = -w0 / vn, w1 = -w1 / vn, w2 = -w2 / vn;
                float h0 = w0 + l0, h1 = w1 + l1, h2 = w2 + l2;
                float hn = std::sqrt(h0 * h0 + h1 * h1 + h2 * h2);
                hn = hn > 1e-6f ? hn : 1e-6f;
                h0 /= hn, h1 /= hn, h2 /= hn;
                const float nh = clampf(n0 * h0 + n1 * h1 + n2 * h2, 0.0f, 1.0f);
                float nv = n0 * w0 + n1 * w1 + n2 * w2;
                nv = nv > 0.05f ? nv : 0.05f;  // grazing pixels: the lobe's 1/(n.v) would explode
                const float r4 = rough * rough * rough * rough;
                const float t = nh * nh * (r4 - 1.0f) + 1.0f;
                const float D = cosl > 0.0f ? r4 / (t * t * (4.0f * kPi) * nv) : 0.0f;
                const float spec = D * highlight * vis;
                s0 += (sun0 * spec + k0) * g0, s1 += (sun1 * spec + k1) * g1,
                    s2 += (sun2 * spec + k2) * g2;
            }
            // a > 1e-5 here
            pS0[i] = clampf(s0 / ac, 0.0f, 1.0f), pS1[i] = clampf(s1 / ac, 0.0f, 1.0f), pS2[i] = clampf(s2 / ac, 0.0f, 1.0f);
        }
#pragma omp simd
        for (int64_t i = 0; i < m; ++i) pS0[i] = srgb(pS0[i]), pS1[i] = srgb(pS1[i]), pS2[i] = srgb(pS2[i]);
        for (int64_t i = 0; i < m; ++i) {
            float* o = out + qbuf[i] * 3;
            const float a = b[kA][i];
            o[0] = b[kS0][i] * a, o[1] = b[kS1][i] * a, o[2] = b[kS2][i] * a;
        }
    }
}
