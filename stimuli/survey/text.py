"""The words a survey shows, all HTML-escaped here, once, so that protocol text is never markup.

A protocol is written by a researcher, but it is still input: an instruction containing ``<script>``
must appear as those characters, not run. Every export builds its HTML through these helpers.

>>> paragraphs("Hello <b>world</b>\\n\\nBye")
'<p>Hello &lt;b&gt;world&lt;/b&gt;</p><p>Bye</p>'
"""

from __future__ import annotations

import html
import re

from stimuli.protocol import Protocol, answer_labels_of, position_labels_of

# Fixed wording of the screens the protocol does not describe (English; edit after import if needed).
PRACTICE_INTRO = "Practice: the next clips are examples to get used to the task. They are not part of the results."
FAMILIARIZATION_INTRO = "Before this part, you will see the characters it shows, one by one."
BLOCK_INTRO = "Part {k} of {n} begins now."
CONTINUE = "Continue"
CONSENT_AGREE = "I agree"
WATCH_FIRST = "You can answer once the clip has played to the end; you may replay it."
END_TEXT = "Thank you! Your answers are being saved."


def escape(text: str) -> str:
    """Text → HTML text (quotes too, so the result is also safe inside an attribute)."""
    return html.escape(str(text), quote=True)


def paragraphs(text: str) -> str:
    """Plain text → ``<p>`` paragraphs (blank lines separate them), escaped."""
    parts = [p.strip() for p in re.split(r"\n\s*\n", str(text)) if p.strip()]
    return "".join(f"<p>{escape(' '.join(p.split()))}</p>" for p in parts)


def position_labels(protocol: Protocol) -> list[str]:
    """What the choices of a forced choice / ranking are called: display labels, else Left/Right."""
    return position_labels_of(protocol)


def answer_labels(protocol: Protocol) -> list[str]:
    """The answer options of one question: Likert labels, or the screen positions."""
    return answer_labels_of(protocol)


def attention_html(protocol: Protocol) -> str:
    """An attention check's request: the protocol's prompt with ``{answer}`` filled in, escaped (or ``""``)."""
    checks = protocol.attention_checks
    if checks is None:
        return ""
    return paragraphs(checks.prompt.replace("{answer}", checks.answer))


def video_html(url: str, width: int, height: int, controls: bool = True) -> str:
    """An inline ``<video>`` (muted, playsinline) scaled to the page width; ``url`` is escaped."""
    control = " controls" if controls else ""
    return (f'<video src="{escape(url)}" width="{int(width)}" height="{int(height)}" preload="auto" playsinline '
            f'muted{control} controlslist="nodownload" disablepictureinpicture '
            f'style="max-width:100%;height:auto"></video>')


def question_html(protocol: Protocol) -> str:
    return f'<p class="shapemotion-question">{escape(protocol.response.question)}</p>'


def instructions_html(protocol: Protocol) -> str:
    """Instructions screen: the protocol's instructions and question, then how answering works."""
    body = paragraphs(protocol.response.instructions) if protocol.response.instructions else ""
    return body + question_html(protocol) + f"<p>{escape(WATCH_FIRST)}</p>"


def consent_html(protocol: Protocol) -> str:
    title = f"<h2>{escape(protocol.title or protocol.name)}</h2>"
    return title + paragraphs(protocol.consent or "")
