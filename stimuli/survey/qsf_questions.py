"""The ``SQ`` elements of a QSF file: one survey question each, with the fields Qualtrics exports.

Question kinds used by the survey export:

- video question, Likert (``MC``/``SAHR``: single answer, horizontal) or forced choice (``MC``/``SAHR``,
  one choice per screen position) or ranking (``RO``/``DND``: drag and drop, one item per position);
- descriptive text (``DB``/``TB``): consent, instructions, familiarisation clips;
- attention check (``MC``/``SAHR``): the protocol's request and the usual answer buttons, no clip.

Every question that shows a clip carries :data:`NEXT_AFTER_VIEW_JS`.
"""

from __future__ import annotations

import re

from stimuli.protocol import Protocol
from stimuli.survey.text import answer_labels, escape

# Qualtrics question JavaScript: hide Next until the clip on the page has played once to the end.
NEXT_AFTER_VIEW_JS = """Qualtrics.SurveyEngine.addOnload(function () {
  /* shapemotion: the Next button appears only after the clip has been watched once to the end */
  var question = this;
  var video = question.getQuestionContainer().querySelector("video");
  if (!video) { return; }
  question.hideNextButton();
  video.addEventListener("ended", function () { question.showNextButton(); }, { once: true });
  var start = video.play();
  if (start && start.catch) { start.catch(function () { video.controls = true; }); }
});
"""


def plain(text: str, limit: int = 100) -> str:
    """HTML → short plain text, as Qualtrics shows in its editor (``QuestionDescription``).

    Qualtrics's own exports decode entities here (``&nbsp;`` in the text, U+00A0 in the description),
    so quotes and ``&`` are decoded; ``&lt;``/``&gt;`` stay encoded, so that protocol markup never
    appears as raw tags anywhere in the file.

    >>> plain("<p>An obese person&#x27;s &quot;walk&quot; &amp; &lt;b&gt;</p>")
    'An obese person\\'s "walk" & &lt;b&gt;'
    >>> plain("Rock&amp;roll"), plain("Rock&amp;roll", limit=6)
    ('Rock&roll', 'Rock')
    """
    flat = " ".join(re.sub(r"<[^>]+>", " ", text).split())
    if len(flat) > limit:   # cut, but never inside an entity
        flat = re.sub(r"&[#a-z0-9]*$", "", flat[:limit])
    return re.sub(r"&(#x27|quot|amp);", lambda m: _TEXT_ENTITIES[m.group(1)], flat)


_TEXT_ENTITIES = {"#x27": "'", "quot": '"', "amp": "&"}


def _element(survey_id: str, payload: dict) -> dict:
    return {"SurveyID": survey_id, "Element": "SQ", "PrimaryAttribute": payload["QuestionID"],
            "SecondaryAttribute": payload["QuestionDescription"], "TertiaryAttribute": None, "Payload": payload}


def _base(tag: str, html_text: str, qtype: str, selector: str, subselector: str | None) -> dict:
    payload = {
        "QuestionText": html_text,
        "DefaultChoices": False,
        "DataExportTag": tag,
        "QuestionType": qtype,
        "Selector": selector,
    }
    if subselector:
        payload["SubSelector"] = subselector
    payload |= {
        "Configuration": {"QuestionDescriptionOption": "UseText"},
        "QuestionDescription": plain(html_text) or tag,
    }
    return payload


def descriptive(survey_id: str, qid: str, tag: str, html_text: str, has_video: bool = False) -> dict:
    """A ``DB`` text/graphic question (no answer, no export column)."""
    payload = _base(tag, html_text, "DB", "TB", None)
    payload |= {"ChoiceOrder": [], "Validation": {"Settings": {"Type": "None"}}, "GradingData": [],
                "Language": [], "NextChoiceId": 4, "NextAnswerId": 1, "QuestionID": qid,
                "DataVisibility": {"Private": False, "Hidden": False}}
    if has_video:
        payload["QuestionJS"] = NEXT_AFTER_VIEW_JS
    return _element(survey_id, payload)


def video_question(survey_id: str, qid: str, tag: str, html_text: str, protocol: Protocol,
                   check: bool = False) -> dict:
    """The answer to one clip: Likert, forced choice or ranking, forced response, Next after one view.
    ``check``: an attention check instead (one answer button to pick, whatever the response type; no clip)."""
    labels = answer_labels(protocol)
    ids = [str(i) for i in range(1, len(labels) + 1)]
    choices = {i: {"Display": escape(label)} for i, label in zip(ids, labels)}
    if protocol.response.type == "ranking" and not check:
        payload = _base(tag, html_text, "RO", "DND", "TX")
        payload["Configuration"] |= {"Stack": False, "StackItemsInBoxes": False}
    else:
        payload = _base(tag, html_text, "MC", "SAHR", "TX")
        payload["Configuration"] |= {"LabelPosition": "BELOW"}
    payload |= {
        "Choices": choices,
        "ChoiceOrder": ids,
        "Validation": {"Settings": {"ForceResponse": "ON", "ForceResponseType": "ON", "Type": "None"}},
        "GradingData": [],
        "Language": [],
        "NextChoiceId": len(ids) + 1,
        "NextAnswerId": 1,
        "QuestionID": qid,
        "RecodeValues": {i: i for i in ids},
        "DataVisibility": {"Private": False, "Hidden": False},
    }
    if not check:
        payload["QuestionJS"] = NEXT_AFTER_VIEW_JS
    return _element(survey_id, payload)
