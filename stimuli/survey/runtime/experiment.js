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
 *   post_trial=URL     also POST each answered trial's data (JSON) to URL as it is given (also
 *                      config.post_trial_url); the static folder needs no server of its own for this
 *
 * Served by `shapemotion serve` (config.server), the page asks the server for its session instead:
 * the server picks the list, stores each answer as it is given (one request at a time, retried on
 * network errors), gives a reloaded page its next unanswered trial, and at the end names the
 * completion URL (redirect=0: stay on the page). URL parameters (PROLIFIC_PID, STUDY_ID, SESSION_ID,
 * …) are passed on to it.
 * Each block's clips are preloaded with a progress bar; a clip that fails to load or play is recorded
 * (failed_video in the data; in server mode also an event with the browser) and its answer buttons
 * are enabled so the participant can go on.
 * With the protocol's attention_checks (config.attention), a check follows every `every`-th test trial
 * (none after the last): attention_check = 1, attention_answer, response_label, attention_passed. A served
 * list has the checks as items already (kind "attention_check"), so they are stored and resumed by position.
 * The server may refuse a request with 429 (rate limit): the page waits the Retry-After it names, then
 * sends the same request again.
 *
 * Layout: the question is moved above the clip and the clip is scaled to the window (fitVideo) so
 * that question, clip and answer buttons fit without scrolling, on a laptop as on a large screen.
 */
(function () {
  "use strict";
  var cfg = window.SHAPEMOTION_CONFIG;
  var PAGE_MARGIN = 12;   // px kept free above and below the trial (rounding, focus outlines)
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
  var simulate = params.get("simulate");
  var postUrl = params.get("post") || cfg.post_url || "";
  var postTrialUrl = params.get("post_trial") || cfg.post_trial_url || "";
  var server = cfg.server ? serverClient() : null;
  var chosen = null, resumed = false, playFailure = null, jsPsych = null;
  window.SHAPEMOTION_STATUS = { done: false, posted: null, list: null, saved: 0, errors: [], failed: [],
                                limited: 0 };

  /** Talks to `shapemotion serve`: one request at a time, so answers arrive in order. */
  function serverClient() {
    var key = "shapemotion:" + cfg.protocol, session = null, queue = Promise.resolve();

    function request(method, path, body) {
      var headers = { "Content-Type": "application/json" };
      if (session) { headers["X-Session-Token"] = session.token; }
      return fetch(path, { method: method, headers: headers, keepalive: true,
                           body: body === undefined ? undefined : JSON.stringify(body) });
    }

    /** Send until the server answers; a 4xx is final (recorded), a network error or 5xx is retried; a rate
     * limit's 429 (it names a Retry-After) is sent again after that wait without using up a try. */
    function send(path, body, tries) {
      return request("POST", path, body).then(function (r) {
        if (limitedFor(r)) { return later(r).then(function () { return send(path, body, tries); }); }
        if (r.status >= 500 && tries > 0) { throw new Error("server " + r.status); }
        return r.json().then(function (answer) {
          if (r.status >= 400) { window.SHAPEMOTION_STATUS.errors.push(r.status + " " + answer.error); }
          return answer;
        });
      }).catch(function (e) {
        if (tries <= 0) { window.SHAPEMOTION_STATUS.errors.push(String(e)); return {}; }
        return new Promise(function (ok) { window.setTimeout(ok, 1000); })
          .then(function () { return send(path, body, tries - 1); });
      });
    }

    /** A 429 of the rate limit: it says when to come back (the per-session cap on clip events is final). */
    function limitedFor(r) { return r.status === 429 && r.headers.get("Retry-After") !== null; }

    /** A promise that resolves once the 429 response's Retry-After (seconds, at least 1) has passed. */
    function later(r) {
      var seconds = Math.max(1, parseInt(r.headers.get("Retry-After"), 10) || 1);
      window.SHAPEMOTION_STATUS.limited += 1;
      return new Promise(function (ok) { window.setTimeout(ok, seconds * 1000); });
    }

    /** Starts or resumes the session, again after a 429's Retry-After (other failures are final). */
    function open(body) {
      return request("POST", "api/sessions", body).then(function (r) {
        if (limitedFor(r)) { return later(r).then(function () { return open(body); }); }
        return r.json().then(function (answer) {
          if (!r.ok) { throw new Error(answer.error || ("server " + r.status)); }
          return answer;
        });
      });
    }

    return {
      start: function () {
        var stored = null, urlParams = {};
        try { stored = JSON.parse(window.localStorage.getItem(key) || "null"); } catch (e) { stored = null; }
        params.forEach(function (value, name) { urlParams[name] = value; });
        return open({ params: urlParams, resume: stored })
          .then(function (state) {
            session = state;
            try { window.localStorage.setItem(key, JSON.stringify({ session: state.session, token: state.token })); }
            catch (e) { /* private mode: a reload then starts over unless the URL carries an id */ }
            return state;
          });
      },
      answer: function (trial, data) {
        var body = { index: trial.index, response: data.response, rt: data.rt };
        queue = queue.then(function () {
          return send("api/sessions/" + session.session + "/trials", body, 30).then(function (answer) {
            if (answer.stored !== undefined) { window.SHAPEMOTION_STATUS.saved += 1; }
          });
        });
      },
      event: function (kind, clip, detail) {
        queue = queue.then(function () {
          return send("api/sessions/" + session.session + "/events", { kind: kind, clip: clip, detail: detail }, 3);
        });
      },
      finish: function () {
        return queue.then(function () { return send("api/sessions/" + session.session + "/finish", {}, 30); });
      }
    };
  }

  /** A clip that did not load or play: in the data, and told to the server. */
  function recordFailure(kind, clip, detail) {
    window.SHAPEMOTION_STATUS.failed.push(kind + ":" + clip);
    if (server) { server.event(kind, clip, detail || ""); }
  }

  /** The answered trial, as it is given: to the study server, or to post_trial=URL. */
  function saveTrial(trial, data) {
    if (server) { server.answer(trial, data); return; }
    if (postTrialUrl) {
      fetch(postTrialUrl, { method: "POST", headers: { "Content-Type": "application/json" }, keepalive: true,
                            body: JSON.stringify(Object.assign({ user_agent: navigator.userAgent }, data)) })
        .then(function () { window.SHAPEMOTION_STATUS.saved += 1; })
        .catch(function (e) { window.SHAPEMOTION_STATUS.errors.push(String(e)); });
    }
  }

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

  /** Outer height of an element, margins included (0 when it is not on the page). */
  function outerHeight(element) {
    if (!element) { return 0; }
    var style = window.getComputedStyle(element);
    return element.getBoundingClientRect().height + parseFloat(style.marginTop) + parseFloat(style.marginBottom);
  }

  /** Scales the clip to the window: the question above and the answers below stay in view without
   * scrolling (a 1280×720 clip alone is taller than a 1366×768 laptop's browser window). */
  function fitVideo() {
    var video = document.getElementById("jspsych-video-button-response-stimulus");
    if (!video) { return; }
    var around = outerHeight(document.getElementById("shapemotion-prompt")) +
      outerHeight(document.getElementById("jspsych-video-button-response-btngroup"));
    var room = { width: document.documentElement.clientWidth - 2 * PAGE_MARGIN,
                 height: window.innerHeight - around - 2 * PAGE_MARGIN };
    // never below a fifth of the clip: on a tiny window the page scrolls rather than show a stamp
    var scale = Math.max(0.2, Math.min(1, room.width / cfg.clip.width, room.height / cfg.clip.height));
    video.style.width = Math.floor(cfg.clip.width * scale) + "px";
    video.style.height = Math.floor(cfg.clip.height * scale) + "px";
  }
  window.addEventListener("resize", fitVideo);

  /** Question above the clip, answers right below it (jsPsych puts the prompt under the buttons). */
  function layoutTrial(video) {
    var prompt = document.getElementById("shapemotion-prompt");
    if (prompt) { video.parentNode.parentNode.insertBefore(prompt, video.parentNode); }
    fitVideo();
  }

  /** Muted inline playback; a click on the clip replays it once it has ended. */
  function prepareVideo() {
    var video = document.getElementById("jspsych-video-button-response-stimulus");
    if (!video) { return; }
    layoutTrial(video);
    video.muted = true;
    video.playsInline = true;
    video.setAttribute("playsinline", "");
    video.addEventListener("click", function () {
      if (video.ended) { video.currentTime = 0; video.play(); }
    });
    // A clip that cannot play must not trap the participant: record it and enable the answers. With
    // <source> children the error fires on the last source, not on the video; NETWORK_NO_SOURCE catches
    // an error that fired before these listeners were attached.
    var clip = window.SHAPEMOTION_STATUS.clip;
    function failed() {
      if (playFailure === clip) { return; }
      playFailure = clip;
      recordFailure("play_failed", clip, video.error ? "media error " + video.error.code : "no playable source");
      document.querySelectorAll("#jspsych-video-button-response-btngroup button")
        .forEach(function (b) { b.disabled = false; });
    }
    video.addEventListener("error", failed);
    var sources = video.querySelectorAll("source");
    if (sources.length) { sources[sources.length - 1].addEventListener("error", failed); }
    window.setTimeout(function () {
      if (video.error || video.networkState === HTMLMediaElement.NETWORK_NO_SOURCE) { failed(); }
    }, 1500);
    // A browser that refuses to autoplay gets the controls, so the participant can start the clip.
    window.setTimeout(function () {
      if (video.paused && !video.ended && video.currentTime === 0) {
        var start = video.play();
        if (start && start.catch) { start.catch(function () { video.controls = true; }); }
      }
    }, 500);
  }

  function videoTrial(trial, choices, extra) {
    var onStart = extra.on_start, onFinish = extra.on_finish;
    extra = Object.assign({}, extra, {
      on_start: function (t) {   // the clip on screen, for automation (preloaded clips play from blob: URLs)
        window.SHAPEMOTION_STATUS.clip = trial.id;
        window.SHAPEMOTION_STATUS.position = trial.index;
        playFailure = null;
        if (onStart) { onStart(t); }
      },
      on_finish: function (data) {
        if (playFailure === trial.id) { data.failed_video = [cfg.clips[trial.id]]; }
        if (onFinish) { onFinish(data); }
      }
    });
    var merged = Object.assign({
      type: jsPsychVideoButtonResponse,
      stimulus: [cfg.clips[trial.id]],
      choices: choices,
      prompt: cfg.text.question + "<p class=\"shapemotion-hint\">" + cfg.text.watch + "</p>",
      width: cfg.clip.width,
      height: cfg.clip.height,
      autoplay: true,
      controls: false,
      response_allowed_while_playing: false,
      on_load: prepareVideo
    }, extra);
    merged.prompt = "<div id=\"shapemotion-prompt\">" + merged.prompt + "</div>";   // moved above the clip
    return merged;
  }

  function familiarization(trial) {
    return videoTrial(trial, [cfg.text.continue], {
      prompt: "<p>" + cfg.text.fam_intro + "</p>",
      data: trialData(trial, false),
      on_finish: function (data) { saveTrial(trial, data); }
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
        saveTrial(trial, data);
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
              saveTrial(trial, data);
            }
          }
        }));
      })(step);
    }
    return steps;
  }

  /** An instructed-response check: the request, the usual answer buttons; the data say whether it was met. */
  function attentionCheck(item) {
    var labels = cfg.response.labels;
    return { type: jsPsychHtmlButtonResponse,
             stimulus: "<div id=\"shapemotion-prompt\">" + cfg.attention.prompt + "</div>",
             choices: cfg.response.labels_html,
             data: { attention_check: 1, attention_answer: cfg.attention.answer },
             on_finish: function (data) {
               data.response_label = labels[data.response];
               data.attention_passed = data.response_label === cfg.attention.answer ? 1 : 0;
               saveTrial(item, data);
             } };
  }

  function screen(html, button, extra) {
    return Object.assign({ type: jsPsychHtmlButtonResponse, stimulus: html, choices: [button] }, extra || {});
  }

  /** Loads one block's clips with a progress bar; a clip that fails is recorded and the study goes on. */
  function preload(trials, block) {
    var clips = trials.filter(function (t) { return t.block === block && t.kind !== "attention_check"; })
      .map(function (t) { return cfg.clips[t.id]; })
      .filter(function (c, i, all) { return all.indexOf(c) === i; });
    return { type: jsPsychPreload, video: clips, auto_preload: false, show_progress_bar: true,
             message: "<p>" + cfg.text.loading + "</p>", error_message: "<p>" + cfg.text.load_error + "</p>",
             continue_after_error: true, max_load_time: 120000,
             on_finish: function (data) {
               (data.failed_video || []).forEach(function (url) { recordFailure("load_failed", String(url)); });
             } };
  }

  /** The list with a check after every `every`-th test trial, none after the last; a served list has them
   * already (the same rule: with_checks in stimuli/serve/study.py). */
  function withChecks(trials) {
    if (server || !cfg.attention) { return trials; }
    var nTests = trials.filter(function (t) { return t.kind === "test"; }).length, tests = 0, out = [];
    trials.forEach(function (trial) {
      out.push(trial);
      if (trial.kind === "test") {
        tests += 1;
        if (tests % cfg.attention.every === 0 && tests < nTests) {
          out.push({ kind: "attention_check", block: trial.block });
        }
      }
    });
    return out;
  }

  function buildTimeline() {
    var trials = withChecks(chosen.trials);
    var timeline = resumed ? [screen(cfg.text.instructions, cfg.text.continue)]
      : [screen(cfg.text.consent, cfg.text.agree), screen(cfg.text.instructions, cfg.text.continue)];
    var nBlocks = trials.reduce(function (m, t) { return Math.max(m, t.block); }, 0);
    var previous = null, loaded = null;
    trials.forEach(function (trial) {
      if (trial.kind === "attention_check") { timeline.push(attentionCheck(trial)); return; }
      if (trial.block !== loaded) { timeline.push(preload(trials, trial.block)); loaded = trial.block; }
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
    if (server) { finishOnServer(); return; }
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

  /** Server mode: wait until every answer is stored, then hand over to the completion URL. */
  function finishOnServer() {
    var display = jsPsych.getDisplayElement();
    display.innerHTML = "<p>" + cfg.text.saving + "</p>";
    server.finish().then(function (answer) {
      window.SHAPEMOTION_STATUS.redirect = answer.redirect || null;
      display.innerHTML = "<p>" + (answer.finished ? cfg.text.saved : cfg.text.save_error) + "</p>";
      window.SHAPEMOTION_STATUS.done = true;
      if (answer.finished && answer.redirect && params.get("redirect") !== "0") {
        window.location.assign(answer.redirect);
      }
    });
  }

  /** Runs the chosen list from its first trial not yet answered. */
  function run() {
    window.SHAPEMOTION_STATUS.list = chosen.list;
    window.SHAPEMOTION_DATA = function () { return jsPsych.data.get().csv(); };   // for automation
    jsPsych = initJsPsych({ on_finish: finish });
    jsPsych.data.addProperties(Object.assign({ participant: participant, list: chosen.list, protocol: cfg.protocol },
                                             chosen.groups));
    var timeline = buildTimeline();
    if (simulate === "data-only" || simulate === "visual") { jsPsych.simulate(timeline, simulate); }
    else { jsPsych.run(timeline); }
  }

  if (!server) { chosen = chooseList(); run(); return; }
  server.start().then(function (state) {
    window.SHAPEMOTION_STATUS.session = state.session;
    participant = state.participant;
    chosen = { list: state.list, groups: state.groups, trials: state.trials };
    resumed = state.next > 0;
    if (state.finished) {   // a finished participant who comes back is handed over again
      document.body.innerHTML = "<p>" + cfg.text.saved + "</p>";
      window.SHAPEMOTION_STATUS.done = true;
      window.SHAPEMOTION_STATUS.redirect = state.redirect;
      if (state.redirect && params.get("redirect") !== "0") { window.location.assign(state.redirect); }
      return;
    }
    run();
  }).catch(function (e) {
    window.SHAPEMOTION_STATUS.errors.push(String(e));
    document.body.innerHTML = "<p>" + cfg.text.start_error + "</p>";
  });
})();
