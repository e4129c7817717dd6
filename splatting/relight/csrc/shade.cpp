// Per-pixel relit shading of composited relight channels: the formula of
// splatting/relight/shading.py (_shade_cm), fused into one pass over the covered pixels, which
// otherwise costs ~80 small torch operations per render (most of relight_render_overhead).
// Serial (a few hundred thousand pixels at most; ~0.2 ms for 22k): deterministic and no thread
// pool contention with the rasterizer's.  Built into the rasterizer's library
// (splatting/raster/build.py SOURCES); called from splatting/relight/render.py::shade_composited.
#include <cmath>
#include <cstdint>
#include <vector>

namespace {
constexpr float kPi = 3.14159265358979323846f;
inline float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }
inline float srgb(float x) {
    x = clampf(x, 0.0f, 1.0f);
    return x <= 0.0031308f ? 12.92f * x : 1.055f * std::pow(x > 1e-12f ? x : 1e-12f, 1.0f / 2.4f) - 0.055f;
}
}  // namespace

// The pixels of rows v0..v1-1, columns u0..u1-1 of a W-wide image whose alpha exceeds 1e-5; the
// box's others are set to 0 (so a caller shading the whole image needs no zero-filled output: one
// pass instead of two over it), pixels outside the box are left as they are.  R: reflectance (albedo + gloss), pixel stride sR, channels
// contiguous; F: relight features (normal 3, [gloss luminance], [roughness], [visibility]), pixel
// stride sF; A: alpha (contiguous).  out: (H W, 3).  prm: l[3] (unit, towards the sun), sun[3] (colour x strength), sky[3],
// fx, fy, cx, cy, Rc[9] (world-to-camera rotation, row-major), roughness, highlight.
// flags: 1 gloss, 2 per-pixel roughness channel, 4 sun visibility channel, 8 in place (out is R,
// pixel stride 3): pixels whose alpha is exactly 0 are left as they are (the compositor's R is 0
// there: no Gaussian reached them), so only covered pixels are written.
extern "C" void rl_shade_f32(int64_t W, int64_t u0, int64_t v0, int64_t u1, int64_t v1, const float* R, int64_t sR,
                             const float* F, int64_t sF, const float* A, float* out, const float* prm, int32_t flags) {
    const float* l = prm;
    const float* sun = prm + 3;
    const float* sky = prm + 6;
    const float fx = prm[9], fy = prm[10], cx = prm[11], cy = prm[12];
    const float* Rc = prm + 13;
    const float rough0 = prm[22], highlight = prm[23];
    const bool gloss = flags & 1, rough_ch = flags & 2, shadows = flags & 4, in_place = flags & 8;
    // per row: the straight linear colours first, then their sRGB encoding in one vectorisable
    // loop (powf is most of the cost; with -ffast-math gcc calls glibc's SIMD powf)
    const int64_t n = u1 > u0 ? u1 - u0 : 0;
    std::vector<float> sbuf(3 * n), abuf(n);
    std::vector<int64_t> qbuf(n);
    for (int64_t q0 = v0 * W; q0 < v1 * W; q0 += W) {
    int64_t m = 0;
    for (int64_t q = q0 + u0; q < q0 + u1; ++q) {
        const float a = A[q];
        if (!(a > 1e-5f)) {  // uncovered: nothing to shade (the torch path's threshold)
            if (!in_place || a != 0.0f) out[3 * q] = out[3 * q + 1] = out[3 * q + 2] = 0.0f;
            continue;
        }
        const float* r = R + q * sR;
        const float* f = F + q * sF;
        const float ac = a > 1e-6f ? a : 1e-6f;
        float alb[3] = {r[0], r[1], r[2]}, gl[3] = {0.0f, 0.0f, 0.0f};
        int c = 3;
        if (gloss) {
            float lum = 0.2126f * r[0] + 0.7152f * r[1] + 0.0722f * r[2];
            lum = lum > 1e-6f ? lum : 1e-6f;
            const float share = clampf(f[c] / lum, 0.0f, 1.0f);
            for (int k = 0; k < 3; ++k) {
                gl[k] = r[k] * share;
                alb[k] = r[k] - gl[k];
            }
            ++c;
        }
        float rough = rough0;
        if (rough_ch) rough = clampf(f[c++] / ac, 0.05f, 1.0f);
        const float vis = shadows ? clampf(f[c] / ac, 0.0f, 1.0f) : 1.0f;
        float n[3] = {f[0], f[1], f[2]};
        float nn = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        nn = nn > 1e-6f ? nn : 1e-6f;
        for (float& x : n) x /= nn;
        float cosl = n[0] * l[0] + n[1] * l[1] + n[2] * l[2];
        cosl = cosl > 0.0f ? cosl : 0.0f;
        const float k = cosl / kPi * vis;
        float lin[3];
        for (int j = 0; j < 3; ++j) lin[j] = (sun[j] * k + sky[j]) * alb[j];
        if (gloss) {
            // the view direction: from the pixel's surface towards the camera, in the world
            const float x = (float(q % W) + 0.5f - cx) / fx, y = (float(q / W) + 0.5f - cy) / fy;
            float v[3];
            for (int j = 0; j < 3; ++j) v[j] = x * Rc[j] + y * Rc[3 + j] + Rc[6 + j];
            const float vn = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
            for (float& e : v) e = -e / vn;
            float h[3] = {v[0] + l[0], v[1] + l[1], v[2] + l[2]};
            float hn = std::sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2]);
            hn = hn > 1e-6f ? hn : 1e-6f;
            for (float& e : h) e /= hn;
            const float nh = clampf(n[0] * h[0] + n[1] * h[1] + n[2] * h[2], 0.0f, 1.0f);
            float nv = n[0] * v[0] + n[1] * v[1] + n[2] * v[2];
            nv = nv > 0.05f ? nv : 0.05f;  // grazing pixels: the lobe's 1/(n.v) would explode
            const float a2 = rough * rough * rough * rough;
            const float t = nh * nh * (a2 - 1.0f) + 1.0f;
            const float D = cosl > 0.0f ? a2 / (t * t * (4.0f * kPi) * nv) : 0.0f;
            const float spec = D * highlight * vis;
            for (int j = 0; j < 3; ++j) lin[j] += (sun[j] * spec + sky[j]) * gl[j];
        }
        for (int j = 0; j < 3; ++j) sbuf[3 * m + j] = clampf(lin[j] / ac, 0.0f, 1.0f);  // a > 1e-5 here
        abuf[m] = a;
        qbuf[m++] = q;
    }
#pragma omp simd
    for (int64_t i = 0; i < 3 * m; ++i) sbuf[i] = srgb(sbuf[i]);
    for (int64_t i = 0; i < m; ++i)
        for (int j = 0; j < 3; ++j) out[qbuf[i] * 3 + j] = sbuf[3 * i + j] * abuf[i];
    }
}
