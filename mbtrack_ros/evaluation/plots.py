"""PNG plots of evaluation results (matplotlib, Agg canvas; no GUI backend, no pyplot state).

* :func:`plot_trajectories`: top view, each track a colour, ground truth dashed grey with ids.
* :func:`plot_localisation_error`: per ground-truth person, distance to its matched track over
  time, gaps where missed.
* :func:`plot_posterior_curves`: posterior-mass curves of several methods (000, Fig. 6).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mbtrack_ros.core.camera import RoomCalibration
from mbtrack_ros.evaluation.clear_mot import ClearMotResult
from mbtrack_ros.evaluation.errors import EvaluationError
from mbtrack_ros.recording.csvfiles import GroundTruthRow, TrackRow

__all__ = ['plot_localisation_error', 'plot_posterior_curves', 'plot_trajectories']


def _figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), dpi=100, layout='constrained')
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, out_png: str | Path) -> Path:
    out_png = Path(out_png)
    try:
        fig.savefig(out_png, format='png')
    except OSError as err:
        raise EvaluationError(f'cannot write {out_png}: {err.strerror or err}') from err
    return out_png


def _by_id(stamps: np.ndarray, ids: np.ndarray) -> dict[int, np.ndarray]:
    """Row indices of each id, in time order."""
    order = np.lexsort((stamps, ids))
    uniq, start = np.unique(ids[order], return_index=True)
    return {int(u): part for u, part in zip(uniq, np.split(order, start[1:]))}


def _gaps(stamps: np.ndarray, values: np.ndarray, step: float) -> np.ndarray:
    """Insert NaN where consecutive stamps are more than 1.5 frame steps apart."""
    if stamps.size < 2 or not np.isfinite(step) or step <= 0:
        return values
    cut = np.flatnonzero(np.diff(stamps) > 1.5 * step) + 1
    return np.insert(values.astype(np.float64), cut, np.nan, axis=0)


def _frame_step(stamps: np.ndarray) -> float:
    u = np.unique(stamps)
    return float(np.median(np.diff(u))) if u.size > 1 else float('nan')


def plot_trajectories(tracks: Sequence[TrackRow], truth: Sequence[GroundTruthRow],
                      out_png: str | Path, *, title: str | None = None,
                      calibration: RoomCalibration | None = None) -> Path:
    """Top view of floor trajectories (metres); with ``calibration`` also the walkable floor
    and the camera positions."""
    fig = _figure(7.0, 6.0)
    ax = fig.add_subplot()
    if calibration is not None:
        x0, y0, x1, y1 = calibration.floor
        ax.plot([x0, x1, x1, x0, x0], [y0, y0, y1, y1, y0], '-', color='0.2', lw=1.0)
        for cam_name, cam in calibration.cameras.items():
            c = cam.center
            ax.plot(c[0], c[1], 's', color='0.2', ms=5)
            ax.annotate(cam_name, (c[0], c[1]), fontsize=7, color='0.2', xytext=(4, -9),
                        textcoords='offset points')
    g_stamp = np.array([r.stamp_ns for r in truth], np.int64)
    g_xy = np.array([(r.x, r.y) for r in truth], np.float64).reshape(-1, 2)
    step = _frame_step(g_stamp)
    for pid, idx in _by_id(g_stamp, np.array([r.person_id for r in truth], np.int64)).items():
        xy = _gaps(g_stamp[idx], g_xy[idx], step)
        ax.plot(xy[:, 0], xy[:, 1], '--', color='0.35', lw=1.3, zorder=3)
        ax.annotate(f'P{pid}', g_xy[idx[0]], color='0.1', fontsize=8, zorder=4,
                    xytext=(3, 3), textcoords='offset points', fontweight='bold')
    t_stamp = np.array([r.stamp_ns for r in tracks], np.int64)
    t_xy = np.array([(r.x, r.y) for r in tracks], np.float64).reshape(-1, 2)
    t_ids = np.array([r.track_id for r in tracks], np.int64)
    step_t = _frame_step(t_stamp) if np.isnan(step) else step
    cmap = [f'C{i}' for i in range(10)]
    for k, (tid, idx) in enumerate(_by_id(t_stamp, t_ids).items()):
        xy = _gaps(t_stamp[idx], t_xy[idx], step_t)
        colour = cmap[k % len(cmap)]
        ax.plot(xy[:, 0], xy[:, 1], '-', color=colour, lw=1.4, zorder=2, label=f'T{tid}')
        ax.plot(*t_xy[idx[0]], 'o', color=colour, ms=4, zorder=2)
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(title or 'trajectories (tracks coloured, ground truth dashed grey)')
    if len(t_ids) and np.unique(t_ids).size <= 20:
        ax.legend(loc='upper left', bbox_to_anchor=(1.01, 1.0), fontsize=7)
    return _save(fig, out_png)


def plot_localisation_error(result: ClearMotResult, out_png: str | Path, *,
                            title: str | None = None) -> Path:
    """Distance to the matched track over time, one line per ground-truth person (mm)."""
    m = result.matches_detail
    if m is None:
        raise EvaluationError('the CLEAR MOT result carries no per-frame matches')
    fig = _figure(9.0, 4.5)
    ax = fig.add_subplot()
    t0 = int(m.stamp_ns.min()) if len(m) else 0
    step = _frame_step(m.stamp_ns)
    for pid, idx in _by_id(m.stamp_ns, m.person_id).items():
        t = (m.stamp_ns[idx] - t0) * 1e-9
        err = _gaps(m.stamp_ns[idx], m.error_m[idx] * 1000.0, step)
        t = _gaps(m.stamp_ns[idx], t, step)
        ax.plot(t, err, '-', lw=1.2, label=f'P{pid}')
        missed = ~m.matched[idx]
        if missed.any():
            ax.plot((m.stamp_ns[idx][missed] - t0) * 1e-9,
                    np.full(int(missed.sum()), result.threshold_m * 1000.0), '|', ms=6,
                    color=ax.lines[-1].get_color(), alpha=0.7)
    ax.axhline(result.threshold_m * 1000.0, color='0.4', lw=0.8, ls=':')
    ax.set_xlabel('time [s]')
    ax.set_ylabel('localisation error [mm]')
    ax.set_ylim(0, result.threshold_m * 1000.0 * 1.08)
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(title or f'{result.name}: error of the matched track (ticks at '
                 f'{result.threshold_m * 1000:.0f} mm: missed)')
    if ax.lines and len(np.unique(m.person_id)) <= 20:
        ax.legend(loc='upper right', fontsize=7, ncol=2)
    return _save(fig, out_png)


def plot_posterior_curves(curves: Mapping[str, tuple[np.ndarray, np.ndarray]],
                          out_png: str | Path, *, title: str | None = None) -> Path:
    """Posterior mass within distance d of the truth: ``{label: (d (D,) m, fraction (D,))}``."""
    if not curves:
        raise EvaluationError('no posterior-mass curves to plot')
    fig = _figure(6.0, 4.5)
    ax = fig.add_subplot()
    for label, (d, frac) in curves.items():
        d, frac = np.asarray(d, np.float64), np.asarray(frac, np.float64)
        if d.shape != frac.shape or d.ndim != 1:
            raise EvaluationError(f'curve {label!r}: distances and fractions must be equal '
                                  f'1-D arrays, got {d.shape} and {frac.shape}')
        ax.plot(d, frac, lw=1.5, label=label)
    ax.set_xlabel('distance from the true position d [m]')
    ax.set_ylabel('posterior mass within d')
    ax.set_ylim(0.0, 1.0)
    ax.set_xlim(left=0.0)
    ax.grid(True, lw=0.4, alpha=0.5)
    ax.set_title(title or 'posterior mass around the ground truth')
    ax.legend(loc='lower right', fontsize=8)
    return _save(fig, out_png)
