/* shapemotion self-hosted survey: runs one participant's trial list of the design with jsPsych 8.
 *
 * Written by `shapemotion survey DIR --format jspsych`; the design lives in config.js
 * (window.SHAPEMOTION_CONFIG). Every text in the config is already HTML-escaped by the exporter.
 *
 * URL parameters:
 *   participant=ID     participant id (recorded); a whole number N also picks the trial list
 *                      ((N - 1) mod lists + 1), which keeps the design's balance over groups
 *   <BETWEEN>=LEVEL    e.g. SEX=F: use only lists of that group (then N indexes within the group)
 *   list=K             use the design participant K's list (overrides the two above)
 *   simulate=data-only|visual   jsPsych simulation mode (for testing)
 *   save=0             do not download the CSV at the end
 *   post=URL           POST the CSV (text/csv) to URL at the end (also config.post_url)
 */
(function () {
  "use strict";
  var cfg = window.SHAPEMOTION_CONFIG;
  var params = new URLSearchParams(window.location.search);

  /** The list (design participant) this run follows. */
  function chooseList() {
    var lists = cfg.lists;
    var explicit = parseInt(params.get("list"), 10);
    if (explicit >= 1) {
      var byNumber = lists.filter(function (l) { return l.list === explicit; });
      if (byNumber.length) { return byNumber[0]; }
    }
    var pool = lists.filter(function (l) {
      return cfg.between.every(function (f) { return !params.has(f) || l.groups[f] === params.get(f); });
    });
    if (!pool.length) { pool = lists; }
    var n = parseInt(params.get("participant"), 10);
    if (!(n >= 1)) { n = 1 + Math.floor(Math.random() * pool.length); }
    return pool[(n - 1) % pool.length];
  }

  var participant = params.get("participant") || ("p" + Math.random().toString(36).slice(2, 10));
  var chosen = chooseList();
  var simulate = params.get("simulate");
  var postUrl = params.get("post") || cfg.post_url || "";
  window.SHAPEMOTION_STATUS = { done: false, posted: null, list: chosen.list };

  var jsPsych = initJsPsych({ on_finish: finish });
  jsPsych.data.addProperties(Object.assign({ participant: participant, list: chosen.list, protocol: cfg.protocol },
                                           chosen.groups));

  function positionsData(trial) {
    var out = {};
    if (trial.positions.length === 2) { out.left = trial.positions[0]; out.right = trial.positions[1]; }
    else if (trial.positions.length > 2) { out.positions = trial.positions.join("|"); }
    return out;
  }

  function trialData(trial, answered) {
    return Object.assign({
      stimulus_id: answered ? trial.id : "", clip_id: trial.id, kind: trial.kind,
      practice: trial.kind === "test" ? 0 : 1, block: trial.block, block_label: trial.block_label,
      trial: trial.trial, repetition: trial.repetition
    }, positionsData(trial));
  }

  /** Muted inline playback; a click on the clip replays it once it has ended. */
  function prepareVideo() {
    var video = document.getElementById("jspsych-video-button-response-stimulus");
    if (!video) { return; }
    video.muted = true;
    video.playsInline = true;
    video.setAttribute("playsinline", "");
    video.addEventListener("click", function () {
      if (video.ended) { video.currentTime = 0; video.play(); }
    });
    // A browser that refuses to autoplay gets the controls, so the participant can start the clip.
    window.setTimeout(function () {
      if (video.paused && !video.ended && video.currentTime === 0) {
        var start = video.play();
        if (start && start.catch) { start.catch(function () { video.controls = true; }); }
      }
    }, 500);
  }

  function videoTrial(trial, choices, extra) {
    var onStart = extra.on_start;
    extra = Object.assign({}, extra, {
      on_start: function (t) {   // the clip on screen, for automation (preloaded clips play from blob: URLs)
        window.SHAPEMOTION_STATUS.clip = trial.id;
        if (onStart) { onStart(t); }
      }
    });
    return Object.assign({
      type: jsPsychVideoButtonResponse,
      stimulus: [cfg.clips[trial.id]],
      choices: choices,
      prompt: cfg.text.question + "<p class=\"shapemotion-hint\">" + cfg.text.watch + "</p>",
      width: cfg.clip.width,
      autoplay: true,
      controls: false,
      response_allowed_while_playing: false,
      on_load: prepareVideo
    }, extra);
  }

  function familiarization(trial) {
    return videoTrial(trial, [cfg.text.continue], {
      prompt: "<p>" + cfg.text.fam_intro + "</p>",
      data: trialData(trial, false)
    });
  }

  function scored(trial) {
    var labels = cfg.response.labels;
    return videoTrial(trial, cfg.response.labels_html, {
      data: trialData(trial, true),
      on_finish: function (data) {
        data.response_label = labels[data.response];
        if (cfg.response.type === "likert") { data.rating = data.response + 1; }
        else { data.chosen = trial.positions[data.response]; }
      }
    });
  }

  /** Ranking: pick the best of the remaining clips until one is left; the last row holds the order. */
  function ranking(trial) {
    var labels = cfg.response.labels, picked = [], steps = [];
    function remaining() { return labels.filter(function (l) { return picked.indexOf(l) < 0; }); }
    function remainingHtml() {   // what the buttons show: the escaped labels of the clips not yet picked
      return remaining().map(function (l) { return cfg.response.labels_html[labels.indexOf(l)]; });
    }
    for (var step = 1; step < labels.length; step++) {
      (function (step) {
        var last = step === labels.length - 1;
        steps.push(videoTrial(trial, function () { return remainingHtml(); }, {
          prompt: cfg.text.question + "<p>" + cfg.text.rank_step.replace("{k}", String(step)) + "</p>",
          response_allowed_while_playing: step > 1,
          on_start: function () { if (step === 1) { picked = []; } },
          data: Object.assign(trialData(trial, last), { rank_step: step }),
          on_finish: function (data) {
            picked.push(remaining()[data.response]);
            data.response_label = picked[picked.length - 1];
            if (last) {
              picked.push(remaining()[0]);
              data.response = picked.slice();
            }
          }
        }));
      })(step);
    }
    return steps;
  }

  function screen(html, button, extra) {
    return Object.assign({ type: jsPsychHtmlButtonResponse, stimulus: html, choices: [button] }, extra || {});
  }

  function buildTimeline() {
    var trials = chosen.trials;
    var clips = trials.map(function (t) { return cfg.clips[t.id]; })
      .filter(function (c, i, all) { return all.indexOf(c) === i; });
    var timeline = [
      { type: jsPsychPreload, video: clips, auto_preload: false, message: "<p>" + cfg.text.loading + "</p>",
        error_message: "<p>" + cfg.text.load_error + "</p>", show_detailed_errors: true,
        continue_after_error: false, max_load_time: 120000 },
      screen(cfg.text.consent, cfg.text.agree),
      screen(cfg.text.instructions, cfg.text.continue)
    ];
    var nBlocks = trials.reduce(function (m, t) { return Math.max(m, t.block); }, 0);
    var previous = null;
    trials.forEach(function (trial) {
      var part = trial.block + ":" + trial.kind;
      if (part !== previous) {
        if (trial.kind === "practice") { timeline.push(screen("<p>" + cfg.text.practice_intro + "</p>", cfg.text.continue)); }
        if (trial.kind === "test" && nBlocks > 1) {
          timeline.push(screen("<p>" + cfg.text.block_intro.replace("{k}", String(trial.block))
            .replace("{n}", String(nBlocks)) + "</p>", cfg.text.continue));
        }
        previous = part;
      }
      if (trial.kind === "familiarization") { timeline.push(familiarization(trial)); }
      else if (cfg.response.type === "ranking") { timeline = timeline.concat(ranking(trial)); }
      else { timeline.push(scored(trial)); }
    });
    timeline.push(screen("<p>" + cfg.text.end + "</p>", cfg.text.finish, { data: { end: 1 } }));
    return timeline;
  }

  function finish() {
    var csv = jsPsych.data.get().csv();
    window.SHAPEMOTION_CSV = csv;
    if (params.get("save") !== "0") {
      jsPsych.data.get().localSave("csv", "shapemotion_" + cfg.protocol + "_" + participant + ".csv");
    }
    var display = jsPsych.getDisplayElement();
    display.innerHTML = "<p>" + cfg.text.saved + "</p>";
    if (!postUrl) { window.SHAPEMOTION_STATUS.done = true; return; }
    fetch(postUrl, { method: "POST", headers: { "Content-Type": "text/csv" }, body: csv })
      .then(function (r) { window.SHAPEMOTION_STATUS.posted = r.status; })
      .catch(function (e) { window.SHAPEMOTION_STATUS.posted = String(e); })
      .then(function () { window.SHAPEMOTION_STATUS.done = true; });
  }

  var timeline = buildTimeline();
  if (simulate === "data-only" || simulate === "visual") { jsPsych.simulate(timeline, simulate); }
  else { jsPsych.run(timeline); }
})();
