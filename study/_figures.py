"""Figures (matplotlib, Agg): image rows with error maps, diagnostics, loss curves.

Images are linear RGB (H, W, 3); they are shown sRGB-encoded and clipped to [0, 1].
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def to_srgb(img: np.ndarray) -> np.ndarray:
    x = np.clip(np.nan_to_num(np.asarray(img, np.float64)), 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def comparison_figure(path: Path, images: dict, errors: dict, mask: np.ndarray, title: str = "") -> Path:
    """Row 1: the images (e.g. reference | default | fitted); row 2: |image - reference| averaged
    over RGB on the water pixels, one shared colour scale."""
    plt = _plt()
    names = list(images)
    ref = images[names[0]]
    n = len(names)
    fig, axes = plt.subplots(2, n, figsize=(3.2 * n, 6.4), squeeze=False)
    vmax = max(float(np.abs(images[k] - ref).mean(-1)[mask].max()) for k in names[1:]) if n > 1 else 1.0
    vmax = max(vmax, 1e-6)
    for j, k in enumerate(names):
        axes[0, j].imshow(to_srgb(images[k]))
        label = k if k not in errors else f"{k}\nRMSE {errors[k]['rmse']:.4f}  FLIP {errors[k]['flip']:.4f}"
        axes[0, j].set_title(label, fontsize=9)
        if j == 0:
            axes[1, j].imshow(mask, cmap="gray")
            axes[1, j].set_title("water pixels scored", fontsize=9)
        else:
            err = np.where(mask, np.abs(images[k] - ref).mean(-1), np.nan)
            im = axes[1, j].imshow(err, cmap="magma", vmin=0, vmax=vmax)
            axes[1, j].set_title(f"|{k} - {names[0]}|", fontsize=9)
    for ax in axes.ravel():
        ax.set_xticks([]); ax.set_yticks([])
    if n > 1:
        fig.colorbar(im, ax=axes[1, :].tolist(), shrink=0.8, label="mean abs. error (linear RGB)")
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def diagnostics_figure(path: Path, maps: dict, mask: np.ndarray, title: str = "") -> Path:
    """One panel per diagnostic map, water pixels only."""
    plt = _plt()
    keys = list(maps)
    fig, axes = plt.subplots(1, len(keys), figsize=(3.2 * len(keys), 3.4), squeeze=False)
    for ax, k in zip(axes[0], keys):
        v = np.where(mask, maps[k], np.nan)
        if k == "denominator":
            v = np.log10(np.maximum(v, 1e-9))
            k = "log10 |denominator|"
        im = ax.imshow(v, cmap="viridis")
        ax.set_title(k, fontsize=9)
        ax.set_xticks([]); ax.set_yticks([])
        fig.colorbar(im, ax=ax, shrink=0.75)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def loss_figure(path: Path, curves: dict, title: str = "") -> Path:
    """Loss (0.5 * sum r^2) against iteration, one line per run, log scale."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for name, ys in curves.items():
        if len(ys):
            ax.semilogy(np.arange(len(ys)), ys, label=name)
    ax.set_xlabel("iteration")
    ax.set_ylabel("loss 0.5 ||r||^2")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path
