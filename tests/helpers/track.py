"""The synthetic vibrating target of the track tests, measured again by
``benchmarks/bench_track.py`` and ``benchmarks/bench_track_parallel.py``."""

from __future__ import annotations

from typing import Any

import numpy as np

from dicblur import speckle_pattern
from dicblur.sequence import Recording
from dicblur.track.synthetic import VibratingTarget


def track_pattern(n: int = 112, seed: int = 1) -> np.ndarray:
    """An n x n speckle pattern (4 px speckles, density 0.5, softness 0.5) stretched to
    30..210 GL: no saturation and no zero grey level in any frame."""
    p = speckle_pattern((n, n), speckle_size=4, density=0.5, softness=0.5, seed=seed)
    return 30 + 180 * (p - p.min()) / (p.max() - p.min())


def vibrating_target(
    pattern: np.ndarray,
    *,
    exposure: float,
    amplitude: float,
    static: int,
    seed: int = 0,
    angle: float = 20.0,
) -> VibratingTarget:
    """``pattern`` vibrating ``amplitude`` px at 200 Hz along ``angle`` deg, filmed at 2000
    fps with ``exposure`` s after ``static`` still frames (peak blur W = A 2 pi f T px)."""
    return VibratingTarget(
        pattern,
        fps=2000.0,
        exposure=exposure,
        amplitude=amplitude,
        frequency=200.0,
        angle=angle,
        static=static,
        seed=seed,
    )


#: Kinds of gross error :func:`corrupted_recording` injects.
CORRUPTIONS = ("foreign", "occlusion", "jump")


def corrupted_recording(
    tgt: VibratingTarget, n_frames: int, *, share: float, size: int, seed: int
) -> tuple[Recording, list[tuple[int, int, int, str]]]:
    """``tgt``'s recording with a ``size`` px square corrupted in ``share`` of the moving
    frames (seeded): a foreign speckle texture pasted, an occlusion (flat grey at the
    patch's mean) or a local jump (the patch's content moved by 3 px, 2 px); returns the
    recording and the patches ``(frame, row, col, kind)``."""
    rng = np.random.default_rng(seed)
    n = tgt.pattern.shape[0]
    moving = np.arange(tgt.static, n_frames)
    hit = rng.choice(moving, max(1, round(share * moving.size)), replace=False)
    foreign = track_pattern(n, seed=seed + 100)
    patches = [
        (int(k), int(rng.integers(24, n - 24 - size)), int(rng.integers(24, n - 24 - size)),
         CORRUPTIONS[i % len(CORRUPTIONS)])
        for i, k in enumerate(sorted(hit.tolist()))
    ]  # fmt: skip
    by_frame: dict[int, list[tuple[int, int, str]]] = {}
    for k, r, c, kind in patches:
        by_frame.setdefault(k, []).append((r, c, kind))

    def read(k: int) -> np.ndarray:
        img = tgt.render(k)
        for r, c, kind in by_frame.get(k, []):
            sl = (slice(r, r + size), slice(c, c + size))
            if kind == "foreign":
                img[sl] = foreign[sl]
            elif kind == "occlusion":
                img[sl] = float(img[sl].mean())
            else:
                img[sl] = img[r + 3 : r + 3 + size, c + 2 : c + 2 + size].copy()
        return img

    rec = Recording(
        source="vibrating target, corrupted patches",
        kind="synthetic",
        n_frames=n_frames,
        shape=(n, n),
        bit_depth=8,
        fps=tgt.fps,
        exposure=tgt.exposure,
        names=[f"frame {i}" for i in range(n_frames)],
        _read=read,
    )
    return rec, patches


def injected_points(
    ds: Any, patches: list[tuple[int, int, int, str]], *, size: int, subset: int, tgt: Any
) -> tuple[np.ndarray, np.ndarray]:
    """Masks (frames, points) of the injected gross errors of ``ds`` (a track of
    :func:`corrupted_recording`): the points whose subset, at its displaced position,
    is at least half covered by a patch, and the points ``flagged`` (an outlier or not
    converged)."""
    frames = ds["frame"].values
    tu, tv, _, _ = tgt.truth(frames)
    pos = {int(f): i for i, f in enumerate(frames)}
    rows, cols = ds["row"].values, ds["col"].values
    h = subset // 2
    injected = np.zeros((frames.size, rows.size), bool)
    for k, r, c, _kind in patches:
        i = pos.get(k)
        if i is None:
            continue
        rr = rows + tv[i]
        cc = cols + tu[i]
        over_r = np.clip(np.minimum(rr + h + 0.5, r + size) - np.maximum(rr - h - 0.5, r), 0, None)
        over_c = np.clip(np.minimum(cc + h + 0.5, c + size) - np.maximum(cc - h - 0.5, c), 0, None)
        injected[i] |= over_r * over_c >= 0.5 * subset * subset
    st = ds["status"].values
    flagged = ds["outlier"].values.astype(bool) | (st != 0)
    return injected & (st != 3), flagged  # a subset out of the frame is not an injected error


def flag_rates(
    n: int, n_frames: int, *, exposure: float = 0.4e-3, share: float = 0.1, seed: int = 0
) -> dict[str, Any]:
    """The track's gross-error flags on a clean ``n`` x ``n`` recording of ``n_frames``
    (:func:`vibrating_target`, 10 px at 200 Hz, 10 static frames giving the noise) and on
    the same recording with 20 px patches (about a subset: a jump of a larger region is
    a motion of it to any neighbour test) corrupted in ``share`` of the moving frames
    (:func:`corrupted_recording`); subset 21, step 10. Returns the shares (%) of the clean
    converged points flagged (``clean_flagged``; by the ZNCC test, ``clean_zncc``, and by
    the median test alone, ``clean_median``), of the injected points caught (``caught``,
    and per kind) and their counts."""
    import dicblur
    from dicblur.track.flags import zncc_flags

    size = 20
    tgt = vibrating_target(track_pattern(n), exposure=exposure, amplitude=10.0, static=10, seed=10)
    kw: dict[str, Any] = {"static": "0:10", "subset": 21, "step": 10, "advice": False}
    clean = dicblur.track(tgt.recording(n_frames), **kw)
    conv = clean["status"].values == 0
    out = clean["outlier"].values.astype(bool)
    low = zncc_flags(clean["zncc"].values, conv)
    res: dict[str, Any] = {
        "n_clean": int(conv.sum()),
        "clean_flagged": 100.0 * float((out & conv).sum()) / max(int(conv.sum()), 1),
        "clean_zncc": 100.0 * float(low.sum()) / max(int(conv.sum()), 1),
        "clean_median": 100.0 * float((out & conv & ~low).sum()) / max(int(conv.sum()), 1),
    }
    rec, patches = corrupted_recording(tgt, n_frames, share=share, size=size, seed=seed)
    ds = dicblur.track(rec, **kw)
    inj, flagged = injected_points(ds, patches, size=size, subset=21, tgt=tgt)
    res["n_injected"] = int(inj.sum())
    res["caught"] = 100.0 * float((inj & flagged).sum()) / max(int(inj.sum()), 1)
    pos = {int(f): i for i, f in enumerate(ds["frame"].values)}
    for kind in CORRUPTIONS:
        mine = [p for p in patches if p[3] == kind]
        m, _ = injected_points(ds, mine, size=size, subset=21, tgt=tgt)
        res[f"caught_{kind}"] = 100.0 * float((m & flagged).sum()) / max(int(m.sum()), 1)
        res[f"n_{kind}"] = int(m.sum())
    res["frames_corrupted"] = len({p[0] for p in patches if p[0] in pos})
    return res


def memory_recording(
    frames: list[np.ndarray], *, fps: float | None = None, exposure: float | None = None
) -> Recording:
    """An 8-bit in-memory :class:`Recording` of ``frames`` (each (rows, cols), GL), with
    ``fps`` and ``exposure`` (s) as a file's header would give them (None: not given)."""
    arr = [np.asarray(f, dtype=np.float64) for f in frames]
    return Recording(
        source="test",
        kind="memory",
        n_frames=len(arr),
        shape=arr[0].shape,
        bit_depth=8,
        fps=fps,
        exposure=exposure,
        names=[f"frame {i}" for i in range(len(arr))],
        _read=lambda i: arr[i],
    )
