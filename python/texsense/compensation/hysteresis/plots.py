"""Figures of a hysteresis model (cf. thesis fig. 4.7-4.9)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt

from texsense.compensation.hysteresis._model import HysteresisModel
from texsense.compensation.hysteresis.validation import ValidationReport
from texsense.data.files import pyplot, save_figure

__all__ = ["model_figure", "validation_figure", "validation_report_figure"]


def model_figure(model: HysteresisModel, path: str | Path) -> Path:
    """Everett surface and the model's major loop with falling curves from 100/70/30 %."""
    plt = pyplot()
    model._check_fitted()
    fig = plt.figure(figsize=(12, 4.8), layout="constrained")
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    k = model.everett_.shape[0]
    g = np.linspace(model.u_min_, model.u_max_, k)
    aa, bb = np.meshgrid(g, g, indexing="ij")
    surf = np.where(bb <= aa, model.everett_, np.nan)
    ax3.plot_surface(aa, bb, surf, cmap="viridis", linewidth=0)
    ax3.set_xlabel(f"α ({model.input_name})")
    ax3.set_ylabel(f"β ({model.input_name})")
    ax3.set_title(f"Everett function F(α, β), {model.method_} method, {k} x {k}")
    ax = fig.add_subplot(1, 2, 2)
    span = model.u_max_ - model.u_min_
    for share in (1.0, 0.7, 0.3):
        top = model.u_min_ + share * span
        cycle = np.concatenate(
            [np.linspace(model.u_min_, top, 200), np.linspace(top, model.u_min_, 200)]
        )
        ax.plot(cycle, model.predict(cycle), lw=1.2, label=f"to {share:.0%} of the input range")
    ax.set_xlabel(f"{model.input_name} [{model.input_unit}]")
    ax.set_ylabel(f"{model.output_name} [{model.output_unit}]")
    ax.set_title("modelled loops")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    path = save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def validation_figure(
    u: npt.ArrayLike,
    measured: npt.ArrayLike,
    modelled: npt.ArrayLike,
    path: str | Path,
    input_label: str = "compression [mm]",
    output_label: str = "pressure [N/cm²]",
    title: str = "",
) -> Path:
    """Measured and modelled output over the input, and the relative error (fig. 4.8/4.9)."""
    plt = pyplot()
    u, y, m = (np.asarray(v, dtype=np.float64) for v in (u, measured, modelled))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), layout="constrained")
    axes[0].plot(u, y, lw=0.8, label="measured")
    axes[0].plot(u, m, lw=0.8, ls="--", label="model")
    axes[0].set_xlabel(input_label)
    axes[0].set_ylabel(output_label)
    axes[0].legend()
    axes[0].grid(alpha=0.3)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(np.abs(y) > 0.05 * np.nanmax(np.abs(y)), (m - y) / y, np.nan)
    axes[1].plot(u, 100 * rel, lw=0.6)
    axes[1].set_xlabel(input_label)
    axes[1].set_ylabel("relative error [%]")
    axes[1].grid(alpha=0.3)
    fig.suptitle(title, fontsize=10)
    path = save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def validation_report_figure(
    report: ValidationReport,
    inputs: npt.ArrayLike,
    outputs: npt.ArrayLike,
    path: str | Path,
    input_label: str = "input",
    output_label: str = "output",
    title: str = "",
) -> Path:
    """Measured vs model over the input (loops) and the error along the record, with the
    worst places of a :class:`texsense.compensation.hysteresis.validation.ValidationReport`
    marked."""
    plt = pyplot()
    u = np.asarray(inputs, dtype=np.float64)
    y = np.asarray(outputs, dtype=np.float64)
    m = report.modelled
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.6), layout="constrained")
    ax.plot(u, y, color="0.2", lw=1.0, label="measured")
    ax.plot(u, m, color="tab:orange", lw=1.0, label="model")
    for n, p in enumerate(report.worst):
        ax.plot([p.input, p.input], [p.measured, p.model], color="tab:red", lw=2)
        ax.annotate(str(n + 1), (p.input, p.model), color="tab:red", fontsize=9)
    ax.set_xlabel(input_label)
    ax.set_ylabel(output_label)
    ax.legend(loc="upper left")
    ax.set_title("measured and modelled (worst places in red)")
    ax2.plot(np.arange(u.size), m - y, color="tab:blue", lw=0.8)
    ax2.axhline(0, color="0.5", lw=0.6)
    for n, p in enumerate(report.worst):
        ax2.annotate(str(n + 1), (p.index, p.model - p.measured), color="tab:red", fontsize=9)
    ax2.set_xlabel("sample")
    ax2.set_ylabel(f"model - measured ({report.unit})")
    ax2.set_title(f"RMSE {report.rmse:.3g} {report.unit}, NRMSE {report.nrmse:.1%}")
    if title:
        fig.suptitle(title)
    path = save_figure(fig, path, dpi=110)
    plt.close(fig)
    return Path(path)
