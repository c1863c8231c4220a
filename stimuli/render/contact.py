"""A contact sheet: every poster of a render as a labelled thumbnail grid (one PNG)."""

from __future__ import annotations

from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

from stimuli.fileio import atomic_write_bytes


def contact_sheet(posters: list[tuple[str, Path]], out: str | Path, columns: int = 8, thumb_width: int = 240) -> Path | None:
    """Tile (caption, poster path) pairs into ``out``; None when there are no posters."""
    posters = [(c, Path(p)) for c, p in posters if Path(p).exists()]
    if not posters:
        return None
    first = Image.open(posters[0][1])
    thumb_height = max(1, int(round(thumb_width * first.height / first.width)))
    caption = 16
    columns = min(columns, len(posters))
    rows = -(-len(posters) // columns)
    sheet = Image.new("RGB", (columns * thumb_width, rows * (thumb_height + caption)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default(size=11)
    for k, (text, path) in enumerate(posters):
        x, y = (k % columns) * thumb_width, (k // columns) * (thumb_height + caption)
        with Image.open(path) as image:
            sheet.paste(image.convert("RGB").resize((thumb_width, thumb_height), Image.LANCZOS), (x, y))
        draw.text((x + 3, y + thumb_height + 2), text[:40], fill=(0, 0, 0), font=font)
    import io

    buffer = io.BytesIO()
    sheet.save(buffer, format="PNG")
    atomic_write_bytes(out, buffer.getvalue())
    return Path(out)
