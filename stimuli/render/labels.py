"""Text labels (A, B, …) drawn over the frames, above (or below) each figure.

The labels never move, so they are rasterised once per clip (Pillow, anti-aliased) into an
alpha mask and blended into each frame with numpy.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from stimuli.render.scene import hex_colour


def _text_colour(background: str, colour: str | None = None) -> tuple[int, int, int]:
    """``colour`` (#rrggbb) if given, else black on light backgrounds and white on dark ones."""
    if colour:
        return tuple(int(round(255 * c)) for c in hex_colour(colour))
    return (0, 0, 0) if sum(hex_colour(background)) > 1.5 else (255, 255, 255)


class LabelOverlay:
    """Labels centred horizontally on each figure's slot, near the top (or the bottom) of the frame."""

    def __init__(self, view, labels: list[str], offsets: list[np.ndarray], background: str,
                 below: bool = False, colour: str | None = None, backdrop: np.ndarray | None = None):
        """``colour`` (#rrggbb) or, by default, black or white against what the labels cover: the
        rendered ``backdrop`` (H, W, 3) under them when given (labels below the figures sit on the
        floor, not on the background colour), else the ``background`` colour."""
        w, h = view.width, view.height
        mask = Image.new("L", (w, h), 0)
        draw = ImageDraw.Draw(mask)
        font = ImageFont.load_default(size=max(10, int(0.075 * h)))
        for label, offset in zip(labels, offsets):
            if not label:
                continue
            x, _ = view.project(np.asarray(offset, float))
            draw.text((float(x), 0.97 * h if below else 0.03 * h), label, fill=255, font=font,
                      anchor="mb" if below else "mt")
        self.alpha = (np.asarray(mask, np.float32) / 255.0)[..., None]
        rows, cols = np.nonzero(self.alpha[..., 0])
        self.box = (rows.min(), rows.max() + 1, cols.min(), cols.max() + 1) if rows.size else None
        self.colour = np.array(_text_colour(background, colour), np.float32)
        if colour is None and backdrop is not None and self.box is not None:
            covered = backdrop[self.alpha[..., 0] > 0.5]
            self.colour = np.full(3, 0.0 if covered.mean() > 127.5 else 255.0, np.float32)

    def apply(self, frame: np.ndarray) -> np.ndarray:
        """Blend the labels into ``frame`` (returns a new array)."""
        if self.box is None:
            return frame
        r0, r1, c0, c1 = self.box
        out = frame.copy()
        a = self.alpha[r0:r1, c0:c1]
        region = out[r0:r1, c0:c1].astype(np.float32)
        out[r0:r1, c0:c1] = (region * (1 - a) + self.colour * a + 0.5).astype(np.uint8)
        return out
