"""Prototype: a light basis learned per swatch, stored as a smooth grid table over the
hemispherical (u, v) disc, fitted by alternating Newton on the binomial deviance with a
roughness penalty on the table (smooth while fitting). Compares held-out RMSE with the
logistic ptm11 and 3-NN interpolation."""
import sys
import time

import numpy as np
import OpenEXR

TRAIN, TEST = sys.argv[1], sys.argv[2]
G = int(sys.argv[3]) if len(sys.argv) > 3 else 17
LAM = float(sys.argv[4]) if len(sys.argv) > 4 else 1e-2
KTERMS = int(sys.argv[5]) if len(sys.argv) > 5 else 11
ITERS = int(sys.argv[6]) if len(sys.argv) > 6 else 8


def load(path):
    f = OpenEXR.File(path)
    h = f.header()
    ch = f.channels()
    names = sorted(n for n in ch if n.startswith("K."))
    K = np.stack([ch[n].pixels.astype(np.float64).ravel() for n in names], axis=1)
    cov = ch["coverage"].pixels.astype(np.float64).ravel()
    dirs = np.array([[float(x) for x in s.split()] for s in h["stack:lightDirs"]])
    return K, cov, dirs


def hemi_uv(d):
    r = np.hypot(d[:, 0], d[:, 1])
    th = np.arctan2(r, d[:, 2])
    s = np.where(r > 1e-12, th / (np.pi / 2) / np.maximum(r, 1e-300), 0.0)
    return d[:, 0] * s, d[:, 1] * s


def monomials(u, v):
    return np.stack([u**3, v**3, u * u * v * v, u * u * v, u * v * v, u * u, v * v, u * v, u, v, np.ones_like(u)], 1)


def bilinear(u, v, G):
    """[L x G*G] weights of the grid table over [-1, 1]^2 at (u, v)."""
    x = (u + 1) / 2 * (G - 1)
    y = (v + 1) / 2 * (G - 1)
    i0 = np.clip(np.floor(x).astype(int), 0, G - 2)
    j0 = np.clip(np.floor(y).astype(int), 0, G - 2)
    fx, fy = x - i0, y - j0
    W = np.zeros((len(u), G * G))
    for di, dj, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(W, (np.arange(len(u)), (j0 + dj) * G + (i0 + di)), w)
    return W


def laplacian(G):
    """Second differences along both axes of the G x G grid: D with ||D b||^2 the roughness."""
    rows = []
    for j in range(G):
        for i in range(1, G - 1):
            r = np.zeros(G * G); r[j * G + i - 1] = 1; r[j * G + i] = -2; r[j * G + i + 1] = 1; rows.append(r)
    for j in range(1, G - 1):
        for i in range(G):
            r = np.zeros(G * G); r[(j - 1) * G + i] = 1; r[j * G + i] = -2; r[(j + 1) * G + i] = 1; rows.append(r)
    return np.array(rows)


def sig(z):
    return 0.5 * (1 + np.tanh(0.5 * z))


def fit_coeffs(K, B, C=None, ridge=1e-5, steps=12):
    """Per texel: logistic regression of K [T x L] on the basis B [L x k] (Newton, ridge)."""
    T, L = K.shape
    k = B.shape[1]
    if C is None:
        C = np.zeros((T, k))
    lam = ridge * np.trace(B.T @ B) / k * 0.25
    for _ in range(steps):
        Z = C @ B.T
        P = sig(Z)
        S = P * (1 - P)
        grad = (P - K) @ B + lam * C
        H = np.einsum("tl,lk,lj->tkj", S, B, B) + lam * np.eye(k)
        step = np.linalg.solve(H, grad[..., None])[..., 0]
        f = lambda C: texel_obj(K, C @ B.T) + 0.5 * lam * np.sum(C * C, 1)
        f0, a = f(C), np.ones(T)
        for _ in range(12):
            bad = f(C - a[:, None] * step) > f0 + 1e-12
            if not bad.any():
                break
            a[bad] *= 0.5
        C = C - a[:, None] * step
    return C


def texel_obj(K, Z):
    P = np.clip(sig(Z), 1e-12, 1 - 1e-12)
    return -np.sum(K * np.log(P) + (1 - K) * np.log(1 - P), 1)


def fit_table(K, C, W, b, D, lam, steps=3):
    """The table b [GG x k]: Newton on sum deviance + lam ||D b||^2 given the coefficients C."""
    GG, k = b.shape
    R = lam * K.shape[0] * np.kron(D.T @ D, np.eye(k))  # parameter order (g, k); per texel
    obj = lambda b: dev(K, C @ (W @ b).T) + 0.5 * b.ravel() @ R @ b.ravel()
    for _ in range(steps):
        B = W @ b
        P = sig(C @ B.T)
        S = P * (1 - P)
        grad_B = (P - K).T @ C  # [L x k]
        grad = (W.T @ grad_B).ravel() + R @ b.ravel()
        Hl = np.einsum("tl,tk,tj->lkj", S, C, C)  # [L x k x k]
        H = np.zeros((GG, k, GG, k))
        for l in range(W.shape[0]):
            nz = np.nonzero(W[l])[0]
            wl = W[l, nz]
            for a, g in enumerate(nz):
                for c, h in enumerate(nz):
                    H[g, :, h, :] += wl[a] * wl[c] * Hl[l]
        H = H.reshape(GG * k, GG * k) + R
        H += 1e-9 * np.trace(H) / len(H) * np.eye(len(H))
        step = np.linalg.solve(H, grad).reshape(GG, k)
        f0, a = obj(b), 1.0
        while a > 1e-4 and obj(b - a * step) > f0:
            a *= 0.5
        b = b - a * step
    return b


def dev(K, Z):
    P = np.clip(sig(Z), 1e-12, 1 - 1e-12)
    return -np.sum(K * np.log(P) + (1 - K) * np.log(1 - P))


Ktr, cov, dtr = load(TRAIN)
Kte, cov2, dte = load(TEST)
m = cov > 0
Ktr, Kte = np.clip(Ktr[m], 0, 1), np.clip(Kte[m], 0, 1)
print(f"{m.sum()} covered texels, {Ktr.shape[1]} training lights, {Kte.shape[1]} held-out lights; grid {G}x{G}, lambda {LAM}, k {KTERMS}")
utr, vtr = hemi_uv(dtr)
ute, vte = hemi_uv(dte)
rmse = lambda Kp: np.sqrt(np.mean((Kp - Kte) ** 2))

# 3-NN inverse-angle interpolation of the training lights (the floor of accuracy.md)
ang = np.arccos(np.clip(dte @ dtr.T, -1, 1))
nn = np.argsort(ang, 1)[:, :3]
w = 1 / np.maximum(np.take_along_axis(ang, nn, 1), 1e-9)
w /= w.sum(1, keepdims=True)
K3 = np.einsum("lj,tlj->tl", w, Ktr[:, nn])
print(f"3-NN: {rmse(K3):.4f}")

t = time.time()
Mtr, Mte = monomials(utr, vtr), monomials(ute, vte)
C11 = fit_coeffs(Ktr, Mtr)
print(f"logistic ptm11 (hemi): {rmse(sig(C11 @ Mte.T)):.4f}  ({time.time() - t:.1f} s)")

# Learned: start from the ptm11 fit with the table holding the monomials (least squares onto
# the grid, so B(l) ~ monomials), then alternate.
Wtr, Wte = bilinear(utr, vtr, G), bilinear(ute, vte, G)
gu, gv = np.meshgrid(np.linspace(-1, 1, G), np.linspace(-1, 1, G))
Mgrid = monomials(gu.ravel(), gv.ravel())
order = list(range(11))[-KTERMS:] if KTERMS <= 11 else None
b = Mgrid[:, order].copy()
C = C11[:, order].copy() if KTERMS < 11 else C11.copy()
D = laplacian(G)
C = fit_coeffs(Ktr, Wtr @ b, C)
print(f"  table init: held-out {rmse(sig(C @ (Wte @ b).T)):.4f}")
for it in range(ITERS):
    t = time.time()
    b = fit_table(Ktr, C, Wtr, b, D, LAM)
    C = fit_coeffs(Ktr, Wtr @ b, C, steps=6)
    print(f"  iter {it}: train dev {dev(Ktr, C @ (Wtr @ b).T) / Ktr.size:.4f}, held-out {rmse(sig(C @ (Wte @ b).T)):.4f} ({time.time() - t:.1f} s)", flush=True)
