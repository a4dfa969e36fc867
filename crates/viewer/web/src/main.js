// The viewer page: local mode (`motionaug view`: one library of clips) and
// service mode (the coordinator: the tenant's datasets and augmentations,
// with live progress and correction curves). Both lead to the same player
// and the same correction panels.

import "./style.css";
import { HttpError, download, followEvents, json, setKey } from "./api.js";
import { Player } from "./player.js";
import { correctionPanels, curvePanel } from "./plots.js";

const $ = (id) => document.getElementById(id);
const KEY_STORE = "motionaug.key";

const state = {
  mode: null,
  clips: [], // descriptors of the open library
  selected: [], // ids in the player
  player: null,
  following: null, // AbortController of the augmentation event stream
  corrections: new Map(), // key -> panel (service, live curves)
};
window.__viewer = state;

function status(text, isError = false) {
  const s = $("status");
  s.textContent = text;
  s.className = isError ? "error" : "";
}

function li(attrs, ...children) {
  const e = document.createElement("li");
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  for (const c of children) e.append(c);
  return e;
}

function span(cls, text) {
  const e = document.createElement("span");
  e.className = cls;
  e.textContent = text;
  return e;
}

function badges(clip) {
  const out = [span("badge", clip.role)];
  const e = clip.entry;
  if (e) {
    if (e.op) out.push(span("badge", e.op));
    if (e.correction) out.push(span(e.correction.accepted ? "badge ok" : "badge bad", e.correction.accepted ? "accepted" : "rejected"));
    if (e.debiased) out.push(span("badge", "debiased"));
    if (e.keyframe !== undefined && e.keyframe !== null) out.push(span("badge", `IK ${e.effector || ""}`));
  }
  if (clip.masked) out.push(span("badge", "masked"));
  return out;
}

function describe(clip) {
  const parts = [];
  if (clip.frames) parts.push(`${clip.frames} frames @ ${Math.round(clip.fps)} Hz`);
  const e = clip.entry;
  if (e && e.source) parts.push(`from ${e.source}`);
  if (e && e.params && Object.keys(e.params).length) parts.push(JSON.stringify(e.params));
  return parts.join(" \u00b7 ");
}

/// Lists `clips` grouped by their group (source clip), each a button that
/// plays it with its versions, and a checkbox that adds it to the comparison.
function showClips(clips) {
  state.clips = clips;
  const list = $("clip-list");
  list.replaceChildren();
  $("clip-count").textContent = `(${clips.filter((c) => c.listed !== false).length})`;
  let group = null;
  for (const clip of clips) {
    if (clip.listed === false) continue;
    if (clip.group !== group) {
      group = clip.group;
      list.append(li({ class: "group" }, group));
    }
    const box = document.createElement("input");
    box.type = "checkbox";
    box.title = "compare: play with the other ticked clips";
    box.checked = state.selected.includes(clip.id);
    box.addEventListener("click", (ev) => {
      ev.stopPropagation();
      const ids = box.checked ? [...state.selected, clip.id] : state.selected.filter((i) => i !== clip.id);
      openClips(ids);
    });
    const item = li({ "data-id": clip.id, "data-name": clip.name, class: "clip" }, box, span("name", clip.name), ...badges(clip), span("sub", describe(clip)));
    item.addEventListener("click", () => openClips(clip.versions && clip.versions.length ? clip.versions : [clip.id]));
    list.append(item);
  }
}

async function openClips(ids) {
  const byId = new Map(state.clips.map((c) => [c.id, c]));
  const clips = ids.map((i) => byId.get(i)).filter(Boolean);
  state.selected = clips.map((c) => c.id);
  for (const item of $("clip-list").querySelectorAll("li.clip")) {
    const on = state.selected.includes(item.dataset.id);
    item.classList.toggle("selected", on);
    item.querySelector("input").checked = on;
  }
  $("empty").hidden = clips.length > 0;
  showPanels(clips);
  try {
    await state.player.open(clips);
  } catch (e) {
    console.warn(e);
    status(e.message, true);
  }
}

async function showPanels(clips) {
  const panels = $("panels");
  panels.replaceChildren();
  const files = clips.filter((c) => c.urls.download);
  if (files.length) {
    const box = document.createElement("div");
    box.className = "panel files";
    box.append("Download: ");
    for (const c of files) {
      const link = document.createElement("a");
      link.href = "#";
      link.className = "file";
      link.textContent = c.name;
      link.addEventListener("click", (e) => {
        e.preventDefault();
        download(c.urls.download, c.name).catch((err) => status(err.message, true));
      });
      box.append(link, " ");
    }
    panels.append(box);
  }
  for (const c of clips) {
    const summary = c.entry && c.entry.correction;
    if (!c.urls.report && !summary) continue;
    let report = null;
    if (c.urls.report) {
      try {
        report = await json(c.urls.report);
      } catch (e) {
        console.warn(e);
      }
    }
    const title = document.createElement("h3");
    title.textContent = `Correction of ${c.name}`;
    title.style.width = "100%";
    panels.append(title, ...correctionPanels(report, summary));
  }
}

// ---- player UI -----------------------------------------------------------

function fmtTime(t) {
  return `${t.toFixed(2)} s`;
}

function playerUi() {
  return {
    onTracks(tracks) {
      const legend = $("legend");
      legend.replaceChildren();
      for (const t of tracks) {
        const sw = span("swatch", "");
        sw.style.background = `#${t.color.getHexString()}`;
        const item = span("", "");
        item.append(sw, t.clip.name.includes(`(${t.clip.role})`) ? t.clip.name : `${t.clip.name} (${t.clip.role})`);
        legend.append(item);
      }
      const keys = $("keyframes");
      keys.replaceChildren();
      const d = tracks.reduce((m, t) => Math.max(m, t.duration()), 0);
      for (const t of tracks) {
        if (!t.meta.ik || d <= 0) continue;
        const mark = span("mark", "");
        mark.style.left = `${(100 * t.meta.ik.keyframe) / t.meta.fps / d}%`;
        mark.title = `${t.clip.name}: IK keyframe ${t.meta.ik.keyframe} (${t.meta.ik.effector_name})`;
        keys.append(mark);
      }
      const scrub = $("scrub");
      scrub.max = String(Math.max(1, Math.round(d * 1000)));
      scrub.value = "0";
    },
    onProgress(tracks) {
      const total = tracks.reduce((s, t) => s + t.frames, 0);
      const loaded = tracks.reduce((s, t) => s + t.loaded, 0);
      status(`loading ${Math.round((100 * loaded) / Math.max(total, 1))} %`);
    },
    onLoaded(tracks, seconds) {
      const frames = tracks.reduce((s, t) => s + t.frames, 0);
      status(`${tracks.length} clip(s), ${frames} frames loaded in ${seconds.toFixed(2)} s`);
    },
    onTime(time, tracks, buffering) {
      if (!tracks.length) {
        $("counter").textContent = "-";
        return;
      }
      const t = tracks[0];
      $("counter").textContent = `${fmtTime(time)} \u00b7 frame ${t.frameAt(time) + 1} / ${t.frames}${buffering ? " (buffering)" : ""}`;
      if (document.activeElement !== $("scrub")) $("scrub").value = String(Math.round(time * 1000));
    },
    onFps(fps) {
      $("fps").textContent = fps === null ? "" : `${fps.toFixed(0)} fps`;
    },
  };
}

function setPlaying(on) {
  state.player.playing = on;
  $("play").innerHTML = on ? "&#10073;&#10073;" : "&#9654;";
}

function wireControls() {
  $("play").addEventListener("click", () => setPlaying(!state.player.playing));
  $("scrub").addEventListener("input", (e) => state.player.seek(Number(e.target.value) / 1000));
  $("speed").addEventListener("change", (e) => (state.player.speed = Number(e.target.value)));
  $("overlay").addEventListener("change", (e) => state.player.setOverlay(e.target.checked));
  document.addEventListener("keydown", (e) => {
    if (e.code === "Space" && e.target.tagName !== "INPUT") {
      e.preventDefault();
      setPlaying(!state.player.playing);
    }
  });
}

// ---- local mode ------------------------------------------------------------

async function local(info) {
  $("title").textContent = info.title;
  const library = await json("api/clips");
  showClips(library.clips);
  status(`${library.clips.length} clips`);
  const first = new URLSearchParams(location.search).get("clip");
  if (first) {
    const clip = library.clips.find((c) => c.name === first || c.id === first);
    if (clip) openClips(clip.versions && clip.versions.length ? clip.versions : [clip.id]);
  }
}

// ---- service mode ----------------------------------------------------------

async function service() {
  $("title").textContent = "service";
  $("login-form").addEventListener("submit", (e) => {
    e.preventDefault();
    const key = $("key").value.trim();
    if (key) signIn(key);
  });
  $("logout").addEventListener("click", () => {
    localStorage.removeItem(KEY_STORE);
    location.reload();
  });
  const saved = localStorage.getItem(KEY_STORE);
  if (saved) signIn(saved);
  else $("login").hidden = false;
}

async function signIn(key) {
  setKey(key);
  try {
    const list = await json("/v1/datasets");
    localStorage.setItem(KEY_STORE, key);
    $("login").hidden = true;
    $("datasets").hidden = false;
    const ul = $("dataset-list");
    ul.replaceChildren();
    for (const d of list.datasets) {
      const item = li({ "data-id": d.id, class: "dataset" }, span("name", d.name), span("badge", `${d.clip_count} clips`));
      item.addEventListener("click", () => openDataset(d.id));
      ul.append(item);
    }
    status(`${list.datasets.length} datasets`);
    const params = new URLSearchParams(location.search);
    if (params.get("dataset")) await openDataset(params.get("dataset"));
    if (params.get("augmentation")) await openAugmentation(params.get("augmentation"));
  } catch (e) {
    setKey(null);
    $("login").hidden = false;
    status(e instanceof HttpError && e.status === 401 ? "unknown or revoked API key" : e.message, true);
  }
}

function mark(listId, id) {
  for (const item of $(listId).querySelectorAll("li")) item.classList.toggle("selected", item.dataset.id === id);
}

async function openDataset(id) {
  mark("dataset-list", id);
  const library = await json(`/v1/datasets/${id}/library`);
  $("title").textContent = library.title;
  showClips(library.clips);
  const augs = await json(`/v1/datasets/${id}/augmentations`);
  $("augmentations").hidden = false;
  const ul = $("augmentation-list");
  ul.replaceChildren();
  for (const a of augs.augmentations) ul.append(augmentationItem(a));
}

function augmentationItem(a) {
  const bar = document.createElement("div");
  bar.className = "progress";
  bar.append(document.createElement("div"));
  const item = li({ "data-id": a.id, class: "augmentation" }, span("name", a.id.slice(0, 8)), span("badge state", a.status), bar, span("sub", ""));
  updateAugmentation(item, a);
  item.addEventListener("click", () => openAugmentation(a.id));
  return item;
}

function updateAugmentation(item, a) {
  item.dataset.progress = String(a.progress);
  item.dataset.status = a.status;
  item.querySelector(".progress > div").style.width = `${(100 * a.progress).toFixed(1)}%`;
  const badge = item.querySelector(".state");
  badge.textContent = a.status;
  badge.className = `badge state ${a.status === "succeeded" ? "ok" : a.status === "failed" ? "bad" : "run"}`;
  const j = a.jobs;
  item.querySelector(".sub").textContent = `${(100 * a.progress).toFixed(0)} % \u00b7 ${j.succeeded}/${j.total} jobs done${j.running ? `, ${j.running} running` : ""}${j.failed ? `, ${j.failed} failed` : ""}`;
}

async function openAugmentation(id) {
  mark("augmentation-list", id);
  if (state.following) state.following.abort();
  const controller = new AbortController();
  state.following = controller;
  state.corrections = new Map();
  $("panels").replaceChildren();
  let lastJobs = null;
  let refreshing = null;
  const refresh = async (a) => {
    const library = await json(`/v1/augmentations/${id}/library`);
    if (controller.signal.aborted) return;
    $("title").textContent = library.title;
    const before = state.selected;
    showClips(library.clips);
    state.selected = before;
    showCorrections(library.corrections);
    showDownload(id, a);
  };
  const onStatus = (a) => {
    let item = $("augmentation-list").querySelector(`li[data-id="${a.id}"]`);
    if (!item) {
      item = augmentationItem(a);
      $("augmentation-list").append(item);
    }
    updateAugmentation(item, a);
    const jobs = JSON.stringify(a.jobs) + a.progress.toFixed(3);
    if (jobs !== lastJobs && !refreshing) {
      lastJobs = jobs;
      refreshing = refresh(a).catch((e) => status(e.message, true)).finally(() => (refreshing = null));
    }
  };
  try {
    onStatus(await json(`/v1/augmentations/${id}`));
    await followEvents(`/v1/augmentations/${id}/events`, (name, data) => {
      if (name === "status") onStatus(JSON.parse(data));
    }, controller.signal);
  } catch (e) {
    if (e.name !== "AbortError") status(e.message, true);
  }
}

function showDownload(id, a) {
  let link = $("panels").querySelector("a.download");
  if (a.status !== "succeeded") return;
  if (!link) {
    link = document.createElement("a");
    link.className = "download";
    link.href = "#";
    link.textContent = "Download the results (zip: BVH, NPZ, manifest.json, reports)";
    link.addEventListener("click", (e) => {
      e.preventDefault();
      download(`/v1/augmentations/${id}/results`, `augmentation-${id}.zip`).catch((err) => status(err.message, true));
    });
    $("panels").prepend(link);
  }
}

/// One curve panel per correction job, updated as its curve grows.
function showCorrections(corrections) {
  for (const c of corrections) {
    let panel = state.corrections.get(c.key);
    const title = `${c.key} \u00b7 ${c.state}${c.state === "running" ? ` ${(100 * c.progress).toFixed(0)} %` : ""}${c.accepted === true ? " \u00b7 accepted" : c.accepted === false ? " \u00b7 rejected" : ""}`;
    if (!panel) {
      panel = curvePanel(title, c.curve);
      panel.dataset.key = c.key;
      state.corrections.set(c.key, panel);
      $("panels").append(panel);
    } else {
      panel.update(c.curve);
      panel.querySelector("h4").textContent = title;
    }
    panel.dataset.points = String(c.curve.length);
  }
}

// ---- start -----------------------------------------------------------------

async function main() {
  try {
    state.player = new Player($("stage"), playerUi());
  } catch (e) {
    $("empty").textContent = `3D view unavailable: ${e.message}`;
    throw e;
  }
  wireControls();
  const info = await json("api/info");
  state.mode = info.mode;
  if (info.mode === "service") await service();
  else await local(info);
  state.ready = true;
}

main().catch((e) => {
  status(e.message, true);
  console.error(e);
});
