#!/usr/bin/python3
"""Reference values for tests/test_image.c (blur) and tests/test_metrics.c (SSIM/PSNR).

Run: /usr/bin/python3 make_image_refs.py   (Debian 12: numpy 1.24, scipy 1.10, scikit-image 0.19)

Inputs are built from an integer hash so C reproduces them bit for bit (no numpy RNG, no libm):
  tn_hash(i)      = lowbias32 (Wellons): h ^= h>>16; h *= 0x7feb352d; h ^= h>>15; h *= 0x846ca68b; h ^= h>>16
  noise(x,y,c,s)  = tn_hash(x + 7919*y + 104729*c + 1000003*s) >> 8          (24-bit integer)
  smooth(x,y,c,s) = bilinear interpolation, in integers, of noise on a grid of 8-pixel cells:
                    ((8-fx)(8-fy)n00 + fx(8-fy)n10 + (8-fx)fy n01 + fx fy n11) >> 6
  pixel value     = integer / 2^24 (exact in float32)
The SSIM references are computed on float64 copies of the float32 images (skimage on float32 input
rounds its intermediate maps to float32 and is itself off by up to ~1e-5 .. 1e-3 for large offsets;
those values are printed as comments for comparison)."""
import numpy as np, scipy, scipy.ndimage as ndi, skimage
from skimage.metrics import structural_similarity, peak_signal_noise_ratio

M32 = 0xFFFFFFFF

def tn_hash(h):
    h = np.asarray(h, dtype=np.uint64) & M32
    h ^= h >> 16; h = (h * 0x7feb352d) & M32
    h ^= h >> 15; h = (h * 0x846ca68b) & M32
    h ^= h >> 16
    return h

def noise(x, y, c, s):
    return (tn_hash(x + 7919 * y + 104729 * c + 1000003 * s) >> 8).astype(np.int64)

def smooth(x, y, c, s):
    gx, gy, fx, fy = x // 8, y // 8, x % 8, y % 8
    n00, n10 = noise(gx, gy, c, s), noise(gx + 1, gy, c, s)
    n01, n11 = noise(gx, gy + 1, c, s), noise(gx + 1, gy + 1, c, s)
    return ((8 - fx) * (8 - fy) * n00 + fx * (8 - fy) * n10 + (8 - fx) * fy * n01 + fx * fy * n11) >> 6

def grid(w, h, ch):
    y, x, c = np.meshgrid(np.arange(h), np.arange(w), np.arange(ch), indexing="ij")
    return x.astype(np.int64), y.astype(np.int64), c.astype(np.int64)

def f32(i, shift=24):
    return (i.astype(np.float64) / float(1 << shift)).astype(np.float32)

# --- SSIM pairs: the same recipes are in test_metrics.c (tm_make_pair) ---------------------
def pair(kind, w, h, ch):
    x, y, c = grid(w, h, ch)
    if kind == 0:   # smooth reference, image = 3/4 reference + 1/4 white noise
        r = smooth(x, y, c, 1); n = noise(x, y, c, 2)
        return f32(r), f32((3 * r + n) >> 2)
    if kind == 1:   # white noise vs a smooth field (low SSIM)
        return f32(noise(x, y, c, 3)), f32(smooth(x, y, c, 4))
    if kind == 2:   # heights around 8192 with a range of 64: float32 precision stress
        r = (1 << 23) + (smooth(x, y, c, 5) >> 8); n = (1 << 23) + (((smooth(x, y, c, 5) >> 8) * 7 + (noise(x, y, c, 6) >> 8)) >> 3)
        return f32(r, 10), f32(n, 10)
    raise ValueError(kind)

def ssim(a, b, R, ch):
    kw = dict(gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=R)
    if ch > 1: kw["channel_axis"] = -1
    else: a, b = a[..., 0], b[..., 0]
    return structural_similarity(a, b, **kw)

print(f"/* made by make_image_refs.py: numpy {np.__version__} scipy {scipy.__version__} skimage {skimage.__version__} */")
print("/* SSIM: kind, w, h, channels, data_range (0 = ref max-min), skimage value on float64 copies */")
cases = [(0, 67, 45, 1, 1.0), (1, 67, 45, 1, 1.0), (0, 40, 33, 3, 1.0), (0, 128, 128, 1, 0.0), (2, 61, 70, 1, 0.0),
         (0, 11, 11, 1, 1.0), (1, 32, 19, 2, 0.5)]
for kind, w, h, ch, R in cases:
    a, b = pair(kind, w, h, ch)
    Ruse = R if R > 0 else float(a.max()) - float(a.min())
    v64 = ssim(a.astype(np.float64), b.astype(np.float64), Ruse, ch)
    v32 = ssim(a, b, Ruse, ch)
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    psnr = 10 * np.log10(Ruse * Ruse / mse)
    print(f"    {{{kind}, {w}, {h}, {ch}, {R!r}, {v64:.12f}, {psnr:.10f}}}, /* float32 skimage: {v32:.9f} */")

# --- blur: scipy.ndimage.gaussian_filter(img, sigma=(s, s, 0), mode='reflect') --------------
print("/* blur: w, h, channels, sigma, then (x, y, c, value) samples */")
for w, h, ch, s in [(37, 29, 2, 0.7), (37, 29, 2, 2.0), (37, 29, 2, 8.0), (100, 90, 3, 8.0), (5, 4, 1, 3.0), (6, 5, 1, 50.0)]:
    x, y, c = grid(w, h, ch)
    img = f32(noise(x, y, c, 7))
    out = ndi.gaussian_filter(img.astype(np.float64), sigma=(s, s, 0), mode="reflect")
    pts = [(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1), (w // 2, h // 2), (1, h // 3), (w - 2, 2)]
    samples = ", ".join(f"{{{px}, {py}, {pc}, {out[py, px, pc]:.9f}}}" for px, py in pts for pc in range(ch) if pc == (px + py) % ch)
    print(f"    {{{w}, {h}, {ch}, {s!r}, {{{samples}}}}},")
