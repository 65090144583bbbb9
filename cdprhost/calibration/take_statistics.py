"""Statistics of a static take: where the effector is, how well that is known, did it move.

Input is the per-frame effector point in the base frame, ``x`` (frames, 3), with the
frame times; NaN marks a frame without a point (a gap). Everything is vectorised over
an optional leading batch axis, ``x`` (takes, frames, 3), so a benchmark can judge
thousands of takes in one call.

Motion-capture noise is not white: a marker's error wanders over a few frames (and
longer when the effector hums on its cables), so a plain standard error of the mean,
std / sqrt(n), is too small by the square root of the correlation time in frames.
Here every standard error comes from the long-run variance, estimated by AR(1)
prewhitening followed by a Newey-West (Bartlett kernel) correction of what the AR(1)
model leaves (Andrews and Monahan, 1992):

1. **Settling.** The effector still swings or sags for a moment after a move. Going
   back from the middle of the take one block at a time, each block is compared
   with the line fitted to everything after it: a block whose mean squared residual
   exceeds what the noise allows (an F quantile at ``settle_alpha``, Bonferroni over
   the blocks, with degrees of freedom from the AR(1) correlation) ends the settled
   part, and it and all earlier frames are trimmed. A linear creep fits the line, so
   it is not mistaken for settling; at most ``max_settling_fraction`` is trimmed.
2. **Outliers.** Frames further than ``outlier_mads`` robust sigmas (median absolute
   deviation from a robust line) from the rest in any coordinate are dropped.
3. **Centre and standard error.** The centre is the mean of the frames kept; its
   standard error per coordinate is sqrt(long-run variance / frames).
4. **Drift.** A line is fitted by feasible GLS (Prais-Winsten rows, AR(1) per
   coordinate) with a Newey-West sandwich covariance; the slope's t statistic with
   ``n_eff - 2`` degrees of freedom (effective sample size of an AR(1) process) gives
   a p-value per coordinate, Bonferroni over the three. ``drift_mm`` is the slope
   times the duration kept.

The verdict (which of these numbers make a take unusable) is
:mod:`cdprhost.calibration.acceptance`'s.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Median absolute deviation -> standard deviation of a normal distribution.
MAD_TO_SIGMA = 1.4826
#: Longest lag of the autocorrelations kept per take (frames).
MAX_LAG = 64
#: Blocks of the settling scan: about one per 8 frames, 4 to 20 of them.
MIN_BLOCKS, MAX_BLOCKS, FRAMES_PER_BLOCK = 4, 20, 8
#: Shorter takes are not scanned for settling (too few frames to tell it from noise).
MIN_SETTLING_FRAMES = 40


@dataclass(frozen=True, eq=False)
class TakeStatistics:
    """Per take (leading batch axis, or none for a single take).

    ``centre`` (3,) mm; ``se`` (3,) standard error of the centre per coordinate;
    ``drift_mm`` (3,) fitted displacement over the frames kept and ``drift_p`` its
    p-value (Bonferroni over coordinates); ``variance_inflation`` (3,) long-run variance
    of the frame noise over its variance (1 for white noise); ``n_eff`` effective number of
    independent frames (smallest over coordinates); ``spread_rms_mm`` RMS distance of
    the frames kept from the centre, ``spread_max_mm`` the largest.
    """

    centre: np.ndarray
    se: np.ndarray
    drift_mm: np.ndarray
    drift_p: np.ndarray
    variance_inflation: np.ndarray
    autocorrelation: np.ndarray  # (3, MAX_LAG + 1) of the residual frame noise
    pairs: np.ndarray  # (MAX_LAG + 1,) frame pairs behind each lag
    n_eff: np.ndarray
    n_frames: np.ndarray  # frames in the take
    n_valid: np.ndarray  # frames with a point
    n_used: np.ndarray  # after trimming the settling and dropping outliers
    n_trimmed: np.ndarray  # settling frames trimmed at the start
    n_outliers: np.ndarray
    settled_at_s: np.ndarray  # time after the take's first frame where the kept part starts
    duration_s: np.ndarray  # duration of the kept part
    spread_rms_mm: np.ndarray
    spread_max_mm: np.ndarray

    @property
    def drift_total_mm(self) -> np.ndarray:
        return np.asarray(np.linalg.norm(self.drift_mm, axis=-1))


# ------------------------------------------------------------------ helpers
def _sum(a: np.ndarray, axis: int = 1) -> np.ndarray:
    return np.asarray(np.sum(a, axis=axis))


def _line(x: np.ndarray, t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted least-squares line per take and coordinate: level at the weighted mean time,
    slope, and that mean time. x (B, n, 3), t (B, n), w (B, n) in {0, 1}."""
    sw = np.maximum(_sum(w), 1.0)
    tbar = _sum(w * t) / sw
    dt = (t - tbar[:, None]) * w
    stt = np.maximum(_sum(dt * dt), 1e-300)
    xz = np.where(w[..., None] > 0, x, 0.0)
    level = _sum(xz * w[..., None]) / sw[:, None]
    slope = _sum(xz * dt[..., None]) / stt[:, None]
    return level, slope, tbar


def _residuals(x: np.ndarray, t: np.ndarray, w: np.ndarray) -> np.ndarray:
    level, slope, tbar = _line(x, t, w)
    r = x - level[:, None, :] - slope[:, None, :] * (t - tbar[:, None])[..., None]
    return np.where(w[..., None] > 0, r, 0.0)


def autocorrelations(r: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Autocorrelations of residual series r (B, n, 3) at lags 0..MAX_LAG over pairs of kept
    frames (w (B, n)), and the number of such pairs per lag (B, L+1) (0 beyond the take).
    Each lag's mean product is tapered by (pairs / frames) so the sequence stays positive
    definite, and divided by the variance; (B, 3, L+1)."""
    n = r.shape[1]
    size = int(2 ** np.ceil(np.log2(max(2 * n, 2))))
    rz = np.where(w[..., None] > 0, r, 0.0)
    fr = np.fft.rfft(rz, n=size, axis=1)
    fw = np.fft.rfft(w, n=size, axis=1)
    lags = min(MAX_LAG, n - 1)
    acf = np.fft.irfft(fr * np.conj(fr), n=size, axis=1)[:, : lags + 1]  # (B, L+1, 3)
    pairs = np.rint(np.fft.irfft(fw * np.conj(fw), n=size, axis=1)[:, : lags + 1])  # (B, L+1)
    n_w = np.maximum(pairs[:, :1], 1.0)
    gamma = np.moveaxis(acf / n_w[..., None], 1, 2)  # biased (1/n) estimator: PD
    g0 = gamma[..., :1]
    corr = np.where(g0 > 0, gamma / np.where(g0 > 0, g0, 1.0), 0.0)
    corr[..., 0] = 1.0
    out = np.zeros(corr.shape[:2] + (MAX_LAG + 1,))
    out[..., : lags + 1] = corr
    cnt = np.zeros((pairs.shape[0], MAX_LAG + 1))
    cnt[:, : lags + 1] = np.maximum(pairs, 0.0)
    return out, cnt


def ar_variance_inflation(corr: np.ndarray, n: np.ndarray, max_order: np.ndarray) -> np.ndarray:
    """Long-run variance over variance, LRV / gamma_0, of series with autocorrelations
    ``corr`` (..., L+1) from ``n`` frames: the autoregression (Levinson-Durbin) of order up
    to ``max_order`` chosen by AIC, LRV = sigma_e^2 / (1 - sum phi)^2 (Den Haan and Levin's
    VARHAC, one series at a time). Clipped to [1, n]: no credit for negative correlation."""
    shape = corr.shape[:-1]
    nn = np.broadcast_to(np.maximum(np.asarray(n, dtype=float), 2.0), shape)
    top = np.broadcast_to(np.asarray(max_order), shape)
    coef = np.zeros(shape + (corr.shape[-1] - 1,))
    err = np.ones(shape)
    best_aic = np.zeros(shape)
    best_vif = np.ones(shape)
    for k in range(1, int(np.max(top, initial=0)) + 1):  # one order at a time, vectorised
        acc = corr[..., k] - np.sum(coef[..., : k - 1] * corr[..., k - 1 : 0 : -1], axis=-1)
        refl = np.clip(acc / np.maximum(err, 1e-300), -0.999, 0.999)
        prev = coef[..., : k - 1].copy()
        coef[..., : k - 1] = prev - refl[..., None] * prev[..., ::-1]
        coef[..., k - 1] = refl
        err = err * (1.0 - refl * refl)
        aic = nn * np.log(np.maximum(err, 1e-300)) + 2.0 * k
        gain = np.maximum(1.0 - np.sum(coef[..., :k], axis=-1), 1e-9)
        better = (aic < best_aic) & (k <= top)
        best_aic = np.where(better, aic, best_aic)
        best_vif = np.where(better, err / gain**2, best_vif)
    return np.asarray(np.clip(best_vif, 1.0, nn))


def max_ar_order(n: np.ndarray) -> np.ndarray:
    """Largest autoregression order tried: 10 log10(n), at most n / 4 and MAX_LAG."""
    nn = np.maximum(np.asarray(n, dtype=float), 2.0)
    return np.asarray(
        np.clip(np.minimum(np.floor(10.0 * np.log10(nn)), nn // 4), 1, MAX_LAG)
    ).astype(int)


def variance_inflation(
    corr: np.ndarray, pairs: np.ndarray, groups: np.ndarray | None = None
) -> np.ndarray:
    """Variance inflation (B, 3) of each take's noise from autocorrelations (B, 3, L+1) and
    pair counts (B, L+1): pooled over takes with the same ``groups`` label (the takes of one
    session share one motion-capture system), else per take.

    The correlation time of mocap noise is a property of the system, not of one take, and a
    take a few correlation times long cannot estimate it (its own slope and level absorb the
    slow part of the noise). Each take's autocorrelation is first corrected for that
    (rho_hat ~ (rho - 2 VIF / n) / (1 - 2 VIF / n)), with the current estimate of VIF, twice."""
    n_takes = corr.shape[0]
    labels = np.arange(n_takes) if groups is None else np.asarray(groups)
    uniq, index = np.unique(labels, return_inverse=True)
    weight = pairs[:, None, :] * np.ones((1, 3, 1))  # (B, 3, L+1)
    frames = pairs[:, 0]
    total = np.zeros(uniq.size)
    np.add.at(total, index, frames)
    vif = np.ones((n_takes, 3))
    for _ in range(3):  # estimate, correct the per-take bias with it, estimate again
        bias = 2.0 * vif / np.maximum(frames, 1.0)[:, None]  # (B, 3)
        fixed = corr * (1.0 - bias[..., None]) + bias[..., None]
        fixed[..., 0] = 1.0
        num = np.zeros((uniq.size, 3, corr.shape[2]))
        den = np.zeros_like(num)
        np.add.at(num, index, fixed * weight)
        np.add.at(den, index, weight)
        pooled = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
        # lags a group never saw are unknown: the order search stops before them
        seen = np.max(np.where(den[:, 0, :] > 0, np.arange(corr.shape[2]), 0), axis=1)
        order = np.minimum(max_ar_order(total), np.maximum(seen, 1))
        group_vif = ar_variance_inflation(pooled, total[:, None], order[:, None])
        vif = group_vif[index]
    return vif


# ------------------------------------------------------------------ settling
def settling_start(
    x: np.ndarray,
    t: np.ndarray,
    w: np.ndarray,
    *,
    max_fraction: float = 0.5,
    alpha: float = 0.01,
    vif: np.ndarray | None = None,
    passes: int = 4,
) -> np.ndarray:
    """Index of the first frame after the settling transient, per take (B,) (see module doc).
    ``vif`` (B, 3): the noise's variance inflation when known (else estimated per take).

    Each pass fits a line to the second half of what is kept and flags every earlier block
    whose mean squared deviation from that line (extrapolated) exceeds what noise and the
    line's own uncertainty allow; the kept part then starts after the last flagged block.
    Passes repeat on the part kept (a slow sag needs more than one), never trimming more than
    ``max_fraction`` of the take."""
    n_takes, n = w.shape
    nb = int(np.clip(n // FRAMES_PER_BLOCK, MIN_BLOCKS, MAX_BLOCKS))
    edges = (np.arange(nb + 1) * n) // nb
    block = np.searchsorted(edges, np.arange(n), side="right") - 1
    jmax = int(np.floor(nb * max_fraction))
    first = np.zeros(n_takes, dtype=int)  # first block kept
    if jmax < 1 or n < MIN_SETTLING_FRAMES:
        return first
    if vif is None:
        ref0 = w * (block >= nb // 2)[None, :]
        vif = variance_inflation(*autocorrelations(_residuals(x, t, ref0), ref0))
    v = np.max(np.broadcast_to(vif, (n_takes, 3)), axis=1)[:, None]  # (B, 1)
    q = 1.0 - alpha / jmax
    counts = np.add.reduceat(w, edges[:-1], axis=1)  # (B, nb) frames per block
    t_block = np.add.reduceat(w * t, edges[:-1], axis=1) / np.maximum(counts, 1.0)
    for _ in range(passes):
        ref_first = (first + nb) // 2  # the second half of the blocks kept
        ref = w * (block[None, :] >= ref_first[:, None])
        level, slope, tbar = _line(x, t, ref)
        r = x - level[:, None, :] - slope[:, None, :] * (t - tbar[:, None])[..., None]
        r = np.where(np.isfinite(r) & (w[..., None] > 0), r, 0.0)
        n_ref = np.maximum(_sum(ref), 1.0)
        s2 = np.maximum(_sum(r * r * ref[..., None]) / n_ref[:, None], 1e-300)
        z2 = _sum(r * r / s2[:, None, :], axis=2)  # (B, n)
        ms = np.add.reduceat(z2, edges[:-1], axis=1) / np.maximum(3.0 * counts, 1.0)
        stt = np.maximum(_sum(ref * (t - tbar[:, None]) ** 2), 1e-300)
        # the extrapolated line's own variance at each block, relative to the frame noise
        lever = (
            v
            / n_ref[:, None]
            * (1.0 + n_ref[:, None] * (t_block - tbar[:, None]) ** 2 / stt[:, None])
        )
        limit = stats.f.ppf(
            q, np.maximum(3.0 * counts / v, 1.0), np.maximum(3.0 * n_ref[:, None] / v, 1.0)
        )
        limit = limit + lever  # its expected share (a shift of the whole block)
        candidate = (np.arange(nb)[None, :] >= first[:, None]) & (np.arange(nb)[None, :] < jmax)
        flagged = candidate & (counts > 0) & (ms > limit)
        last = np.max(np.where(flagged, np.arange(nb)[None, :], -1), axis=1)
        moved = last + 1 > first
        if not moved.any():
            break
        first = np.where(moved, last + 1, first)
    return np.asarray(edges[first])


# ------------------------------------------------------------------ outliers
def _masked_median(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-gap takes: judged elsewhere
        return np.asarray(np.nanmedian(np.where(w > 0, a, np.nan), axis=1))


def spike_mask(
    x: np.ndarray, t: np.ndarray, w: np.ndarray, n_mads: float, min_scale: float, window: int = 5
) -> np.ndarray:
    """Isolated outlier frames (B, n): beyond ``n_mads`` robust sigmas of a robust line while
    most of their ``window`` neighbours are not (a swing or sag is beyond in runs, a marker
    swap or reflection in one or two frames). Removed before the settling scan."""
    beyond = w.astype(bool) & ~outlier_mask(x, t, w, n_mads, min_scale)
    half = window // 2
    padded = np.pad(beyond.astype(float), ((0, 0), (half + 1, half)))
    csum = np.cumsum(padded, axis=1)
    runs = csum[:, window:] - csum[:, :-window]  # beyond-count in each centred window
    return np.asarray(beyond & (runs <= half))


def outlier_mask(
    x: np.ndarray, t: np.ndarray, w: np.ndarray, n_mads: float, min_scale: float
) -> np.ndarray:
    """Frames (B, n) within ``n_mads`` robust sigmas of a robust line in every coordinate.

    The line joins the medians of the first and second half of the frames kept, so a
    creep is not mistaken for outliers."""
    tm = _masked_median(t, w)
    h1 = w * (t <= tm[:, None])
    h2 = w * (t > tm[:, None])
    t1, t2 = _masked_median(t, h1), _masked_median(t, h2)
    x1 = _masked_median(x, h1[..., None] * np.ones(3))
    x2 = _masked_median(x, h2[..., None] * np.ones(3))
    span = t2 - t1
    ok = np.isfinite(span) & (span > 0)
    slope = np.where(ok[:, None], (x2 - x1) / np.where(ok, span, 1.0)[:, None], 0.0)
    level = np.where(ok[:, None], x1, _masked_median(x, w[..., None] * np.ones(3)))
    t0 = np.where(ok, t1, tm)
    r = np.abs(x - level[:, None, :] - slope[:, None, :] * (t - t0[:, None])[..., None])
    scale = np.maximum(MAD_TO_SIGMA * _masked_median(r, w[..., None] * np.ones(3)), min_scale)
    scale = np.where(np.isfinite(scale), scale, min_scale)
    inside = np.all(np.where(np.isfinite(r), r, np.inf) <= n_mads * scale[:, None, :], axis=2)
    return np.asarray((w > 0) & inside)


# ------------------------------------------------------------------ centre, SE, drift
def take_statistics(
    x: np.ndarray,
    t: np.ndarray,
    valid: np.ndarray | None = None,
    *,
    outlier_mads: float = 5.0,
    min_scale_mm: float = 0.005,
    max_settling_fraction: float = 0.5,
    settle_alpha: float = 0.01,
    groups: np.ndarray | None = None,
    noise_inflation: np.ndarray | None = None,
) -> TakeStatistics:
    """Judge-ready statistics of static takes (see module doc).

    ``x`` (frames, 3) or (takes, frames, 3) in mm, NaN for gaps; ``t`` frame times (s),
    broadcastable to (takes, frames); ``valid`` an extra mask of usable frames. The noise's
    correlation is pooled over takes with the same ``groups`` label (default: each take on
    its own), or given as ``noise_inflation`` (takes, 3), e.g. pooled over a session by
    :func:`variance_inflation` from earlier results' ``autocorrelation`` and ``pairs``."""
    pts = np.asarray(x, dtype=float)
    single = pts.ndim == 2
    if single:
        pts = pts[None]
    n_takes, n, _ = pts.shape
    times = np.broadcast_to(np.asarray(t, dtype=float), (n_takes, n)).astype(float)
    ok = np.isfinite(pts).all(axis=2) & np.isfinite(times)
    if valid is not None:
        ok &= np.broadcast_to(np.asarray(valid, dtype=bool), ok.shape)
    times = np.where(np.isfinite(times), times, 0.0)
    w = ok.astype(float)
    given = None if noise_inflation is None else np.broadcast_to(noise_inflation, (n_takes, 3))
    spikes = spike_mask(pts, times, w, outlier_mads, min_scale_mm)
    start = settling_start(
        pts,
        times,
        w * ~spikes,
        max_fraction=max_settling_fraction,
        alpha=settle_alpha,
        vif=given,
    )
    kept = ok & (np.arange(n)[None, :] >= start[:, None])
    inl = outlier_mask(pts, times, kept.astype(float), outlier_mads, min_scale_mm)
    wu = inl.astype(float)
    n_used = _sum(wu)
    centre, slope, tbar = _line(pts, times, wu)
    resid = pts - centre[:, None, :] - slope[:, None, :] * (times - tbar[:, None])[..., None]
    resid = np.where(inl[..., None], resid, 0.0)
    corr, pairs = autocorrelations(resid, wu)
    vif = variance_inflation(corr, pairs, groups) if given is None else np.asarray(given)
    n_div = np.maximum(n_used, 1.0)[:, None]
    # the residual variance misses the variance of the fitted level and slope, ~2 LRV / n
    gamma0 = _sum(resid * resid) / n_div / np.maximum(1.0 - 2.0 * vif / n_div, 0.2)
    lrv = gamma0 * vif  # long-run variance per frame, (B, 3)
    stt = _sum(wu * (times - tbar[:, None]) ** 2)
    v_level = lrv / n_div
    # cross-coordinate long-run covariance: the lag-0 correlation scaled by each coordinate's
    # long-run standard deviation (the coordinates share the markers' noise and its spectrum)
    cov0 = np.einsum("bni,bnj->bij", resid, resid)
    sd0 = np.sqrt(np.maximum(np.einsum("bii->bi", cov0), 1e-300))
    corr0 = cov0 / (sd0[:, :, None] * sd0[:, None, :])
    lsd = np.sqrt(lrv)
    v_slope = corr0 * lsd[:, :, None] * lsd[:, None, :] / np.maximum(stt, 1e-300)[:, None, None]
    n_eff = n_used[:, None] / vif
    dof = np.clip(np.min(n_eff, axis=1) - 2.0, 1.0, np.maximum(n_used - 2.0, 1.0))
    ridge = 1e-12 * np.einsum("bii->b", v_slope)[:, None, None] * np.eye(3)
    with np.errstate(invalid="ignore", divide="ignore"):
        wald = np.einsum(
            "bi,bi->b", slope, np.linalg.solve(v_slope + ridge, slope[..., None])[..., 0]
        )
    wald = np.where(np.isfinite(wald) & (n_used >= 4), wald, 0.0)
    p = stats.f.sf(wald / 3.0, 3, dof)
    tu = np.where(inl, times, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        t_lo, t_hi = np.nanmin(tu, axis=1), np.nanmax(tu, axis=1)
        t_first = np.nanmin(np.where(ok, times, np.nan), axis=1)
    duration = np.where(n_used > 0, t_hi - t_lo, 0.0)
    floor = min_scale_mm / np.sqrt(np.maximum(n_used, 1.0))
    se = np.maximum(np.sqrt(np.where(np.isfinite(v_level), v_level, np.inf)), floor[:, None])
    dist = np.linalg.norm(np.where(inl[..., None], pts - centre[:, None, :], 0.0), axis=2)
    out = TakeStatistics(
        centre=centre,
        se=se,
        drift_mm=slope * duration[:, None],
        drift_p=p,
        variance_inflation=vif,
        autocorrelation=corr,
        pairs=pairs,
        n_eff=np.min(n_eff, axis=1),
        n_frames=np.full(n_takes, n),
        n_valid=ok.sum(axis=1),
        n_used=n_used.astype(int),
        n_trimmed=(ok & ~kept).sum(axis=1),
        n_outliers=(kept & ~inl).sum(axis=1),
        settled_at_s=np.where(n_used > 0, t_lo - t_first, 0.0),
        duration_s=duration,
        spread_rms_mm=np.sqrt(_sum(dist * dist) / np.maximum(n_used, 1.0)),
        spread_max_mm=np.max(dist, axis=1),
    )
    if single:
        return TakeStatistics(**{k: np.asarray(v)[0] for k, v in vars(out).items()})
    return out
