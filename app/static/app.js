// The service's web page: search by dropping a mesh, enroll, browse the gallery, see
// the calibration. Plain ES modules, no build step; three.js is vendored (static/vendor).
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { bestTurn } from "/static/align.js";

const $ = (id) => document.getElementById(id);

// A clickable element that the keyboard reaches too: Enter or Space does what a click does.
function onActivate(element, action) {
  element.addEventListener("click", action);
  element.addEventListener("keydown", (e) => {
    if (e.key === "Enter" || e.key === " ") {
      e.preventDefault();
      action();
    }
  });
}
const PAGE = 24;

// Only the newest request of a kind is shown: one answering late, after a newer sort,
// file or collection, is dropped. request(kind) returns whether it is still the newest.
const newest = {};
function request(kind) {
  const mine = (newest[kind] || 0) + 1;
  newest[kind] = mine;
  return () => newest[kind] === mine;
}
const KEY = "modalshape-api-key";
const COLLECTION = "modalshape-collection";

// The collection the page works on; the default one's resources have the paths without
// /collections/{name}.
let collection = localStorage.getItem(COLLECTION) || "default";
const base = () => (collection === "default" ? "" : `/collections/${encodeURIComponent(collection)}`);

// --------------------------------------------------------------------------- API
class ApiError extends Error {
  constructor(status, code, detail) {
    super(detail);
    this.status = status;
    this.code = code;
  }
}

function keyHeaders() {
  const key = sessionStorage.getItem(KEY);
  return key ? { "X-API-Key": key } : {};
}

async function api(path, { method = "GET", body = null, retry = true } = {}) {
  const headers = keyHeaders();
  let response;
  try {
    response = await fetch(path, { method, body, headers });
  } catch (err) {
    throw new ApiError(0, "unreachable", "The service does not answer; is it running?");
  }
  if (response.status === 401 && retry) {
    await askForKey();
    return api(path, { method, body, retry: false });
  }
  if (response.status === 204) return null;
  const type = response.headers.get("content-type") || "";
  const data = type.includes("json") ? await response.json() : null;
  if (!response.ok) {
    const detail = (data && data.detail) || `The service answered ${response.status}.`;
    throw new ApiError(response.status, (data && data.error) || "error", detail);
  }
  return data;
}

function askForKey() {
  return new Promise((resolve) => {
    const dialog = $("key-dialog");
    $("key-form").onsubmit = () => {
      sessionStorage.setItem(KEY, $("key-input").value);
      resolve();
    };
    dialog.showModal();
    $("key-input").focus();
  });
}

function showError(err) {
  const alert = $("alert");
  alert.textContent = err instanceof ApiError ? err.message : String(err.message || err);
  alert.hidden = false;
}

function clearError() {
  $("alert").hidden = true;
}

// --------------------------------------------------------------------------- tabs
const TABS = ["search", "enroll", "gallery", "calibration"];

function selectTab(name) {
  for (const tab of TABS) {
    const selected = tab === name;
    $(`tab-${tab}`).setAttribute("aria-selected", String(selected));
    $(`view-${tab}`).hidden = !selected;
  }
  clearError();
  if (name === "gallery") loadGallery();
  if (name === "calibration") loadCalibration();
  status();
}

for (const tab of TABS) $(`tab-${tab}`).addEventListener("click", () => selectTab(tab));

// --------------------------------------------------------------------------- 3D views
const loader = new GLTFLoader();

class Viewer {
  constructor(canvas) {
    this.canvas = canvas;
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setClearColor(0xeef1f5);
    this.scene = new THREE.Scene();
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x444455, 1.4));
    const light = new THREE.DirectionalLight(0xffffff, 1.6);
    light.position.set(2, 3, 4);
    this.scene.add(light);
    this.camera = new THREE.PerspectiveCamera(40, 4 / 3, 0.01, 100);
    this.camera.position.set(1.9, 1.0, 2.4); // three-quarter view, 3.2 from the centre
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener("change", () => this.render());
    this.models = [];
    new ResizeObserver(() => this.resize()).observe(canvas);
  }

  // A front view (y up) wide enough for `count` shapes side by side.
  frontView(count) {
    this.camera.position.set(0, 0.45, 1.7 + 1.4 * count);
    this.controls.target.set(0, 0, 0);
    this.controls.update();
  }

  resize() {
    const { clientWidth: w, clientHeight: h } = this.canvas;
    if (!w || !h) return;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  // The previews at `urls`, side by side in one frame, each within the unit sphere.
  async show(...urls) {
    loader.setRequestHeader(keyHeaders());
    const loaded = await Promise.all(urls.map((url) => loader.loadAsync(url)));
    for (const model of this.models) this.scene.remove(model);
    this.models = loaded.map((gltf, i) => {
      const model = new THREE.Group();
      model.add(gltf.scene);
      // Previews are in the engine's canonical frame (largest spread across, least
      // towards the viewer, limbs down). One made before that is in its file's own
      // axes: z up (TOSCA, scans) turned to y.
      if (!gltf.scene.getObjectByName(CANONICAL_NODE)) gltf.scene.rotation.x = -Math.PI / 2;
      gltf.scene.traverse((node) => {
        if (node.isMesh) {
          node.material = new THREE.MeshStandardMaterial({
            color: i === 0 ? 0x8ca8cc : 0xb7a07a, roughness: 0.6, side: THREE.DoubleSide,
          });
          node.geometry.computeVertexNormals();
        }
      });
      model.position.x = 1.15 * (2 * i - (urls.length - 1));
      this.scene.add(model);
      return model;
    });
    this.resize();
    return loaded.map((gltf) => points(gltf.scene));
  }

  render() {
    this.renderer.render(this.scene, this.camera);
  }
}

// The glTF node of a preview in the canonical frame (worker/jobs/previews.py).
const CANONICAL_NODE = "canonical-frame";

// A model's vertices as [x, y, z], in its scene's frame (the canonical node's transform
// applied).
function points(scene) {
  scene.updateMatrixWorld(true);
  const out = [];
  const v = new THREE.Vector3();
  scene.traverse((node) => {
    if (!node.isMesh) return;
    const position = node.geometry.attributes.position;
    for (let i = 0; i < position.count; i++) {
      v.fromBufferAttribute(position, i).applyMatrix4(node.matrixWorld);
      out.push([v.x, v.y, v.z]);
    }
  });
  return out;
}

let compareViewer, detailViewer;
function viewers() {
  if (!compareViewer) {
    compareViewer = new Viewer($("view-compare"));
    detailViewer = new Viewer($("view-detail"));
  }
}

// --------------------------------------------------------------------------- cards
// Below this share of an enrolled file's surface described, say that the rest was left
// out (as the command line's PARTIAL_SURFACE in app/client.py and the service's notes on
// a query).
const PARTIAL_SURFACE = 0.99;

function partial(kept) {
  return kept != null && kept < PARTIAL_SURFACE;
}

// The point cloud a file was, as a phrase; null for a mesh.
function pointCloud(facts) {
  if (!facts || facts.input_points == null) return null;
  const points = `a scanner's point cloud: ${facts.input_points.toLocaleString("en")} points`;
  let read = `${points}, triangulated as one view`;
  if (facts.input_hidden != null) {
    const hidden = facts.input_hidden.toLocaleString("en");
    read = `${points} seen from where most of it shows, triangulated as that view (${hidden} hidden behind them left out)`;
  }
  if (facts.input_grid) {
    const [width, height] = facts.input_grid;
    read = `${points} on a ${width} x ${height} grid, triangulated by it`;
  }
  if (!facts.input_support) return read;
  const support = facts.input_support.toLocaleString("en");
  return `${read} (${support} points of a floor, table or wall it stood on or against left out)`;
}

function percent(value) {
  return `${(100 * value).toFixed(value < 0.1 ? 1 : 0)}%`;
}

// What stands in a card for a mesh without a thumbnail yet (or ever).
const NO_THUMBNAIL = { queued: "queued", processing: "being described" };

function thumbnail(id, name, status, error) {
  if (status === "failed") return placeholder(`failed: ${error || "not described"}`);
  if (status !== "ready") return placeholder(NO_THUMBNAIL[status] || status);
  const img = document.createElement("img");
  const path = `${base()}/meshes/${id}/thumbnail`;
  img.alt = `Thumbnail of ${name}`;
  img.onerror = () => img.replaceWith(placeholder("no preview"));
  const headers = keyHeaders();
  if (!headers["X-API-Key"]) {
    img.src = path;
  } else { // an <img> cannot send the key: fetched with it, shown from memory
    fetch(path, { headers })
      .then((r) => (r.ok ? r.blob() : Promise.reject(new Error(r.statusText))))
      .then((blob) => { img.src = URL.createObjectURL(blob); })
      .catch(() => img.onerror());
  }
  return img;
}

function placeholder(text) {
  const div = document.createElement("div");
  div.className = "placeholder";
  div.textContent = text;
  return div;
}

function matchCard(match, result) {
  const card = document.createElement("div");
  card.className = "card";
  card.tabIndex = 0;
  card.setAttribute("role", "button");
  card.dataset.meshId = match.mesh_id;
  card.append(thumbnail(match.mesh_id, match.name, "ready"));
  const title = document.createElement("div");
  title.className = "title";
  title.textContent = `${match.rank}. ${match.name}`;
  const meta = document.createElement("div");
  meta.className = "meta label";
  meta.textContent = match.label || "(no label)";
  const score = document.createElement("div");
  score.className = "meta";
  score.textContent = `score ${match.score.toPrecision(3)}`;
  if (match.confidence !== null) score.textContent += `, confidence ${percent(match.confidence)}`;
  else if (match.fitness !== null && match.fitness !== undefined) {
    score.textContent += `, holds ${percent(match.fitness)} of the view`;
    score.title = "fitted rigidly: the share of the view that lies on this match's surface";
  } else if (result.partial) score.textContent += ", no confidence (ranked by its parts)";
  card.append(title, meta, score);
  if (match.accepted !== null) {
    const verdict = document.createElement("div");
    verdict.className = match.accepted ? "accepted" : "rejected";
    verdict.textContent = match.accepted ? "accepted" : "not the same object";
    card.append(verdict);
  }
  // Why it matched: for each modality that ranked (a weight above 0), how close the
  // match is on one scale for every query and collection: the share of the collection's
  // pairs of different objects that are farther apart (a full bar: closer than all).
  const bars = document.createElement("div");
  bars.className = "bars";
  for (const modality of result.modalities) {
    const value = match.scores[modality];
    const closeness = match.closeness ? match.closeness[modality] : undefined;
    const name = document.createElement("span");
    name.textContent = modality.toUpperCase();
    const bar = document.createElement("div");
    bar.className = "bar";
    bar.dataset.modality = modality;
    const fill = document.createElement("span");
    if (closeness === undefined) {
      bar.title = `${modality} dissimilarity ${value.toPrecision(3)}; the collection has no `
        + "pairs to compare it with yet";
      fill.style.width = "0%";
    } else {
      bar.dataset.closeness = String(closeness);
      bar.title = `${modality}: closer than ${percent(closeness)} of the collection's pairs `
        + `of different objects (dissimilarity ${value.toPrecision(3)})`;
      fill.style.width = `${Math.max(2, 100 * closeness)}%`;
    }
    bar.append(fill);
    bars.append(name, bar);
  }
  card.append(bars);
  onActivate(card, () => compare(match, result, card));
  return card;
}

function showResults(result, target) {
  const cards = result.matches.map((m) => matchCard(m, result));
  target.replaceChildren(...cards);
  $("compare").hidden = true;
  if (!cards.length) target.replaceChildren(placeholder("The gallery is empty."));
  else compare(result.matches[0], result, cards[0]); // the best match beside the query
  status();
}

function forgetResults() {
  request("search"); // a search still running is not shown
  $("search-results").replaceChildren();
  $("search-progress").textContent = "";
  $("compare").hidden = true;
}

// A deleted mesh leaves the search results, and the 3D view if it was the match shown.
function forgetMesh(id) {
  for (const card of document.querySelectorAll(`#search-results .card[data-mesh-id="${id}"]`)) {
    if (card.classList.contains("selected")) $("compare").hidden = true;
    card.remove();
  }
}

// The query (left) and the match (right) in one 3D view, the match turned to face as
// the query does (align.js).
async function compare(match, result, card) {
  for (const other of document.querySelectorAll(".card.selected")) other.classList.remove("selected");
  card.classList.add("selected");
  viewers();
  $("compare").hidden = false;
  $("caption-query").textContent = result.queryName ? `Query: ${result.queryName}` : "Query";
  $("caption-match").textContent = `Match ${match.rank}: ${match.name} (${match.label || "no label"})`;
  const canvas = $("view-compare");
  try {
    const urls = [result.preview, `${base()}/meshes/${match.mesh_id}/preview`].filter(Boolean);
    const shapes = await compareViewer.show(...urls);
    let turn = [1, 1, 1];
    if (shapes.length === 2) {
      turn = bestTurn(shapes[0], shapes[1]).turn;
      compareViewer.models[1].scale.set(...turn);
    }
    canvas.dataset.models = String(shapes.length);
    canvas.dataset.turn = turn.join(",");
    compareViewer.frontView(shapes.length);
  } catch (err) {
    showError(err);
  }
}

// --------------------------------------------------------------------------- search
const dropzone = $("drop-search");
onActivate(dropzone, () => $("file-search").click());
dropzone.addEventListener("dragover", (e) => {
  e.preventDefault();
  dropzone.classList.add("over");
});
dropzone.addEventListener("dragleave", () => dropzone.classList.remove("over"));
dropzone.addEventListener("drop", (e) => {
  e.preventDefault();
  dropzone.classList.remove("over");
  if (e.dataTransfer.files.length) search(e.dataTransfer.files[0]);
});
$("file-search").addEventListener("change", (e) => {
  if (e.target.files.length) search(e.target.files[0]);
});

async function search(file) {
  clearError();
  const form = new FormData();
  form.append("file", file);
  form.append("k", $("search-k").value || "8");
  if ($("search-far").value) form.append("far", $("search-far").value);
  const progress = $("search-progress");
  const started = performance.now();
  forgetResults();
  const current = request("search");
  const tick = setInterval(() => {
    if (!current()) return;
    const seconds = ((performance.now() - started) / 1000).toFixed(0);
    progress.textContent = `Describing ${file.name}: ${seconds} s (a few seconds for a new mesh)`;
  }, 250);
  try {
    const result = await api(`${base()}/query`, { method: "POST", body: form });
    if (!current()) return;
    result.queryName = file.name;
    const how = { computed: "described now", enrolled: "enrolled already", recent: "searched recently" };
    // The service's own sentences on the query: the point cloud it was, the part of the
    // file left out, how partial it looks or that it was smoothed.
    progress.textContent = `${file.name}: ${result.matches.length} matches among ${result.gallery_size} `
      + `enrolled (${how[result.descriptor_source] || result.descriptor_source}, `
      + `${((performance.now() - started) / 1000).toFixed(1)} s).`
      + (result.notes || []).map((note) => ` ${note}`).join("");
    showResults(result, $("search-results"));
  } catch (err) {
    if (!current()) return;
    progress.textContent = "";
    showError(err);
  } finally {
    clearInterval(tick);
  }
}

// --------------------------------------------------------------------------- enroll
$("enroll-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  clearError();
  const files = [...$("enroll-files").files];
  const label = $("enroll-label").value.trim();
  const table = $("enroll-table");
  table.hidden = false;
  const rows = files.map((file) => {
    const row = document.createElement("tr");
    row.innerHTML = "<td></td><td></td><td>uploading</td>";
    row.cells[0].textContent = file.name;
    table.tBodies[0].append(row);
    return row;
  });
  await Promise.all(files.map(async (file, i) => {
    const form = new FormData();
    form.append("file", file);
    if (label) form.append("label", label);
    try {
      const mesh = await api(`${base()}/meshes`, { method: "POST", body: form });
      rows[i].cells[1].textContent = `#${mesh.id} ${mesh.name}`;
      follow(mesh.id, rows[i].cells[2]);
    } catch (err) {
      rows[i].cells[2].textContent = `failed: ${err.message}`;
      rows[i].cells[2].className = "rejected";
    }
  }));
});

async function follow(meshId, cell) {
  for (;;) {
    let mesh;
    try {
      mesh = await api(`${base()}/meshes/${meshId}`);
    } catch (err) {
      cell.textContent = err.message;
      return;
    }
    cell.textContent = mesh.status === "failed" ? `failed: ${mesh.detail}` : mesh.status;
    cell.className = { ready: "accepted", failed: "rejected" }[mesh.status] || "";
    if (mesh.status === "ready" || mesh.status === "failed") return status();
    await new Promise((resolve) => setTimeout(resolve, 1000));
  }
}

// --------------------------------------------------------------------------- gallery
let galleryOffset = 0;

async function loadGallery() {
  const current = request("gallery");
  const params = new URLSearchParams({
    offset: galleryOffset, limit: PAGE, sort: $("gallery-sort").value,
  });
  if ($("gallery-label").value.trim()) params.set("label", $("gallery-label").value.trim());
  if ($("gallery-status").value) params.set("status", $("gallery-status").value);
  try {
    const page = await api(`${base()}/meshes?${params}`);
    if (!current()) return;
    const grid = $("gallery-grid");
    grid.replaceChildren(...page.items.map(galleryCard));
    if (!page.items.length) grid.replaceChildren(placeholder("Nothing enrolled matches."));
    const last = Math.min(page.offset + page.items.length, page.total);
    $("gallery-page").textContent = page.total ? `${page.offset + 1}-${last} of ${page.total}` : "";
    $("gallery-prev").disabled = page.offset === 0;
    $("gallery-next").disabled = last >= page.total;
  } catch (err) {
    if (current()) showError(err);
  }
}

function galleryCard(mesh) {
  const card = document.createElement("div");
  card.className = "card";
  card.tabIndex = 0;
  card.setAttribute("role", "button");
  card.dataset.meshId = mesh.id;
  card.append(thumbnail(mesh.id, mesh.name, mesh.status, mesh.error));
  const title = document.createElement("div");
  title.className = "title";
  title.textContent = mesh.name;
  const meta = document.createElement("div");
  meta.className = "meta";
  meta.textContent = `${mesh.label || "(no label)"}, ${mesh.status}`;
  card.append(title, meta);
  onActivate(card, () => openDetail(mesh));
  return card;
}

let detailMesh = null;

async function openDetail(mesh) {
  detailMesh = mesh;
  $("detail").hidden = false;
  $("detail").scrollIntoView({ block: "start" });
  $("detail-name").textContent = `#${mesh.id} ${mesh.name}`;
  const cloud = mesh.descriptor && pointCloud(mesh.descriptor);
  const facts = {
    label: mesh.label || "(none)",
    status: mesh.status === "failed" ? `failed: ${mesh.detail}` : mesh.status,
    file: `${mesh.filename} (${(mesh.size_bytes / 1024).toFixed(0)} kB)`,
    vertices: mesh.descriptor
      ? `${mesh.descriptor.input_vertices.toLocaleString("en")} in the file`
        + (cloud ? ` (${cloud})` : "")
        + `; the descriptor resampled it to ${mesh.descriptor.vertices.toLocaleString("en")}`
      : "-",
    surface: mesh.descriptor && mesh.descriptor.kept_area_fraction != null
      ? `${percent(mesh.descriptor.kept_area_fraction)} described`
        + (partial(mesh.descriptor.kept_area_fraction)
          ? " (its largest connected part; the file's other, separate parts were left out)"
          : "")
        + (mesh.descriptor.smoothed ? ", smoothed of a scanner's noise" : "")
      : "-",
    described: mesh.descriptor ? `${mesh.descriptor.timings.total.toFixed(2)} s, ${mesh.descriptor.preset} v${mesh.descriptor.preset_version}` : "-",
    metadata: JSON.stringify(mesh.metadata),
    enrolled: new Date(mesh.created_at).toLocaleString(),
  };
  $("detail-meta").replaceChildren(...Object.entries(facts).flatMap(([k, v]) => {
    const dt = document.createElement("dt");
    dt.textContent = k;
    const dd = document.createElement("dd");
    dd.textContent = v;
    return [dt, dd];
  }));
  $("detail-similar").disabled = mesh.status !== "ready";
  viewers();
  if (mesh.status === "ready") {
    try {
      await detailViewer.show(`${base()}/meshes/${mesh.id}/preview`);
    } catch (err) {
      showError(err);
    }
  }
}

$("detail-similar").addEventListener("click", async () => {
  if (!detailMesh) return;
  const current = request("search");
  try {
    const result = await api(`${base()}/meshes/${detailMesh.id}/similar?k=${$("search-k").value || 8}`, { method: "POST" });
    if (!current()) return;
    result.queryName = detailMesh.name;
    selectTab("search");
    $("search-progress").textContent = `Most similar to ${detailMesh.name}:`;
    showResults(result, $("search-results"));
  } catch (err) {
    if (!current()) return;
    forgetResults(); // not the results of another search beside this error
    showError(err);
  }
});

$("detail-delete").addEventListener("click", async () => {
  if (!detailMesh) return;
  if (!window.confirm(`Delete ${detailMesh.name} (#${detailMesh.id}) and its file? This cannot be undone.`)) return;
  try {
    await api(`${base()}/meshes/${detailMesh.id}`, { method: "DELETE" });
    forgetMesh(detailMesh.id);
    $("detail").hidden = true;
    detailMesh = null;
    loadGallery();
    status(); // the header's count
  } catch (err) {
    showError(err);
  }
});

$("gallery-sort").addEventListener("change", () => {
  galleryOffset = 0;
  loadGallery();
});
$("gallery-filter").addEventListener("submit", (e) => {
  e.preventDefault();
  galleryOffset = 0;
  loadGallery();
});
$("gallery-prev").addEventListener("click", () => {
  galleryOffset = Math.max(0, galleryOffset - PAGE);
  loadGallery();
});
$("gallery-next").addEventListener("click", () => {
  galleryOffset += PAGE;
  loadGallery();
});

// --------------------------------------------------------------------------- calibration
async function loadCalibration() {
  const summary = $("calibration-summary");
  const current = request("calibration");
  try {
    const c = await api(`${base()}/calibration`);
    if (!current()) return;
    summary.textContent = `${c.labelled_shapes} labelled meshes (${c.labels} labels): `
      + `${c.genuine_pairs} pairs of the same label, ${c.impostor_pairs} of different labels. `
      + `Equal error rate ${percent(c.eer)}. `
      + (c.trusted
        ? "Enough pairs to trust these rates."
        : `Few pairs, so these are rough estimates; trusted rates need ${c.trust_rule.split(";")[0]}.`);
    // With no error at any threshold the ROC lies on its axes and says nothing: the
    // scores' spread shows how wide the gap between the two kinds of pairs is.
    const separated = c.eer === 0;
    $("calibration-roc").toggleAttribute("hidden", separated); // an SVG element has no .hidden
    if (!separated) drawRoc(c.roc, c.eer);
    drawHistogram(c.histogram);
    const separation = $("calibration-separation");
    separation.hidden = !separated;
    if (separated) {
      const gap = gapOf(c.histogram);
      separation.textContent = "No error at any threshold: every pair of meshes with the same "
        + "label scores below every pair with different labels"
        + (gap ? ` (the closest pair of different labels scores ${gap.toFixed(1)} times the `
          + "farthest pair of the same label, at the histogram's resolution)" : "")
        + ". The ROC is flat on its axes; the scores' spread is drawn instead.";
    }
    fillRows($("calibration-table"), c.operating_points.map((p) =>
      [percent(p.far), p.threshold === null ? "accepts nothing" : p.threshold.toPrecision(3),
        percent(p.estimated_far), percent(p.estimated_frr)]));
    $("calibration-table").hidden = false;
    showFusion(c.fusion);
  } catch (err) {
    if (!current()) return;
    summary.textContent = err.message;
    for (const id of ["calibration-roc", "calibration-histogram"]) $(id).toggleAttribute("hidden", true);
    for (const id of ["calibration-table", "calibration-fusion", "calibration-fusion-numbers",
      "calibration-folds", "calibration-separation"]) $(id).hidden = true;
  }
}

// How far apart the two kinds of pairs lie, in bins of the histogram: the ratio of the
// lowest impostor bin's lower edge to the highest genuine bin's upper edge (null when
// they overlap).
function gapOf({ edges, genuine, impostor }) {
  const lastGenuine = genuine.reduce((last, n, i) => (n ? i : last), -1);
  const firstImpostor = impostor.findIndex((n) => n > 0);
  if (lastGenuine < 0 || firstImpostor <= lastGenuine) return null;
  return edges[firstImpostor] / edges[lastGenuine + 1];
}

// One row of cells per list of texts, in the table's body.
function fillRows(table, rows) {
  table.tBodies[0].replaceChildren(...rows.map((texts) => {
    const row = document.createElement("tr");
    for (const text of texts) {
      const cell = document.createElement("td");
      cell.textContent = text;
      row.append(cell);
    }
    return row;
  }));
}

// The weights the fused score uses: learned on the labelled meshes, the preset's, or
// pinned; a modality's comparison is named where it is not the preset's. Then the
// cross-validation that chose them, fold by fold, beside the preset's weights.
function showFusion(fusion) {
  const weighed = (weights, comparisons) => Object.entries(weights).map(([m, w]) =>
    `${m.toUpperCase()} ${w}`
    + (comparisons[m] && comparisons[m] !== fusion.preset_comparisons[m] ? ` (${comparisons[m]})` : ""))
    .join(", ");
  const source = { learned: "learned on this gallery", preset: "the preset's", pinned: "pinned by the operator" };
  $("calibration-fusion").textContent = `Fusion weights: ${weighed(fusion.weights, fusion.comparisons)} `
    + `(${source[fusion.source] || fusion.source}). ${fusionSentence(fusion)}`;
  $("calibration-fusion").hidden = false;
  // The cross-validation's figures, for whoever wants them, folded under the sentence.
  const numbers = $("calibration-fusion-numbers");
  numbers.hidden = !fusion.adoption;
  if (fusion.adoption) {
    const a = fusion.adoption;
    numbers.querySelector("p").textContent = `Held out, the learned weights scored EER `
      + `${percent(fusion.held_out.eer)} and mAP ${percent(fusion.held_out.map)}; the preset's `
      + `${percent(fusion.preset_held_out.eer)} and ${percent(fusion.preset_held_out.map)}. `
      + `Gain ${(100 * a.gain).toFixed(2)} points of the loss (the mean of EER and 1 - mAP); `
      + `corrected resampled t ${a.statistic.toFixed(2)} against ${a.critical.toFixed(2)} `
      + `(one-sided, 95%): ${a.adopted ? "adopted" : "not adopted"}.`;
  }
  const folds = $("calibration-folds");
  folds.hidden = fusion.folds.length === 0;
  if (folds.hidden) return;
  // Rounds of the folds, each dealt from its own seed: every round holds each mesh out once.
  const rounds = fusion.rounds;
  const perRound = fusion.folds.length / rounds;
  const test = fusion.adoption;
  folds.querySelector("summary").textContent = `How the fusion was chosen: ${fusion.folds.length} `
    + `folds in ${rounds} round${rounds > 1 ? "s" : ""}`
    + (test ? `, a gain of ${(100 * test.gain).toFixed(2)} points over the preset's `
      + `(${test.adopted ? "beyond" : "within"} the folds' noise)` : "");
  const scores = (s) => [(100 * s.eer).toFixed(1) + "%", (100 * s.map).toFixed(1) + "%"];
  fillRows(folds.querySelector("table"), [
    ...fusion.folds.map((f, i) => [String(Math.floor(i / perRound) + 1), String((i % perRound) + 1),
      String(f.held_out_shapes), weighed(f.weights, f.comparisons), ...scores(f.held_out), ...scores(f.preset)]),
    ["mean", "", String(fusion.labelled_shapes), "", ...scores(fusion.held_out), ...scores(fusion.preset_held_out)],
  ]);
}

// Why the weights are these, as a person would say it (the figures are folded below).
function fusionSentence(fusion) {
  const a = fusion.adoption;
  const shapes = `${fusion.labelled_shapes} labelled meshes`;
  if (fusion.source === "learned" && a) {
    return `Weights learned on this collection's ${shapes} ranked better in cross-validation `
      + "than the preset's, by more than the folds disagree, so they are used.";
  }
  if (fusion.source === "preset" && a) {
    return `Weights learned on this collection's ${shapes} did not rank better in `
      + "cross-validation than the preset's by more than the folds disagree, so the "
      + "preset's stay.";
  }
  return `${fusion.reason.charAt(0).toUpperCase()}${fusion.reason.slice(1)}.`;
}

// The fused scores of pairs of the same label (genuine) and of different labels
// (impostor), counted per bin on a log axis.
function drawHistogram({ edges, genuine, impostor }) {
  const svg = $("calibration-histogram");
  const [x0, y0, w, h] = [40, 20, 360, 220];
  const bins = genuine.length;
  const top = Math.max(...genuine, ...impostor, 1);
  const bar = (counts, colour, offset) => counts.map((n, i) => {
    const height = (h * n) / top;
    const x = x0 + (w * i) / bins + offset;
    return `<rect x="${x.toFixed(1)}" y="${(y0 + h - height).toFixed(1)}" width="${(w / bins / 2).toFixed(1)}" height="${height.toFixed(1)}" fill="${colour}"/>`;
  }).join("");
  const tick = (i) => `<text x="${(x0 + (w * i) / bins).toFixed(1)}" y="${y0 + h + 16}" text-anchor="middle">${edges[i].toPrecision(2)}</text>`;
  svg.innerHTML = `
    <rect x="${x0}" y="${y0}" width="${w}" height="${h}" fill="#fff" stroke="#d5dbe3"/>
    ${bar(genuine, "#2e7d4f", 0)}${bar(impostor, "#a33a2f", w / bins / 2)}
    ${tick(0)}${tick(Math.floor(bins / 2))}${tick(bins)}
    <text x="${x0 + w / 2 - 70}" y="${y0 + h + 32}">fused score (log)</text>
    <text x="${x0 + 6}" y="${y0 + 14}" style="fill:#2e7d4f">same label: ${genuine.reduce((a, b) => a + b, 0)} pairs</text>
    <text x="${x0 + 6}" y="${y0 + 28}" style="fill:#a33a2f">different labels: ${impostor.reduce((a, b) => a + b, 0)} pairs</text>`;
  svg.toggleAttribute("hidden", false);
}

function drawRoc(roc, eer) {
  const svg = $("calibration-roc");
  const [x0, y0, w, h] = [62, 20, 340, 240];
  const minFar = 1e-3;
  const x = (far) => x0 + (w * (Math.log10(Math.max(far, minFar)) - Math.log10(minFar))) / -Math.log10(minFar);
  const y = (frr) => y0 + h * (1 - frr);
  const points = roc.far.map((far, i) => `${x(far).toFixed(1)},${y(roc.frr[i]).toFixed(1)}`).join(" ");
  const ticks = [0.001, 0.01, 0.1, 1].map((f) => `<text x="${x(f)}" y="${y0 + h + 16}" text-anchor="middle">${percent(f)}</text>`).join("");
  svg.innerHTML = `
    <rect x="${x0}" y="${y0}" width="${w}" height="${h}" fill="#fff" stroke="#d5dbe3"/>
    <polyline points="${points}" fill="none" stroke="#2c5f9e" stroke-width="2"/>
    <line x1="${x(eer)}" y1="${y0}" x2="${x(eer)}" y2="${y0 + h}" stroke="#a33a2f" stroke-dasharray="4 3"/>
    ${ticks}
    <text x="${x0 + w / 2 - 90}" y="${y0 + h + 32}">false acceptance rate (log)</text>
    <text x="4" y="${y0 + 10}">FRR 100%</text><text x="18" y="${y0 + h}">0%</text>
    <text x="${x(eer) + 4}" y="${y0 + 14}">EER ${percent(eer)}</text>`;
  svg.toggleAttribute("hidden", false);
}

// --------------------------------------------------------------------------- collections
// The picker lists the collections the key may read; each has its own meshes and calibration.
// Called with the header's status: the options are relabelled in place (an open list
// stays open) and rebuilt only when collections came or went.
async function loadCollections() {
  const select = $("collection");
  try {
    const { items } = await api("/collections");
    if (!items.some((c) => c.name === collection) && items.length) collection = items[0].name;
    const label = (c) => `${c.name} · ${c.ready} ready${c.units === "metric" ? " · metric" : ""}`;
    const same = select.options.length === items.length
      && items.every((c, i) => select.options[i].value === c.name);
    if (same) {
      items.forEach((c, i) => { select.options[i].textContent = label(c); });
    } else {
      select.replaceChildren(...items.map((c) => {
        const option = document.createElement("option");
        option.value = c.name;
        option.textContent = label(c);
        return option;
      }));
    }
    select.value = collection;
    const chosen = items.find((c) => c.name === collection);
    $("collection-help").textContent = chosen ? `units ${chosen.units}, preset ${chosen.preset}` : "";
  } catch (err) {
    showError(err);
  }
}

$("collection").addEventListener("change", () => {
  collection = $("collection").value;
  localStorage.setItem(COLLECTION, collection);
  forgetResults();
  $("detail").hidden = true;
  detailMesh = null;
  galleryOffset = 0;
  const open = TABS.find((tab) => !$(`view-${tab}`).hidden);
  selectTab(open || "search"); // which refreshes the status and the picker
});

// --------------------------------------------------------------------------- start
async function status() {
  try {
    const ready = await fetch("/ready").then((r) => r.json());
    const progress = ready.descriptors;
    const behind = progress && progress.described < progress.enrolled
      ? `; describing with ${progress.preset}: ${progress.described} of ${progress.enrolled} done`
      : "";
    $("service-status").textContent = ready.status === "ready" ? `index: ${ready.checks.index}${behind}` : "starting...";
  } catch {
    $("service-status").textContent = "service unreachable";
  }
  loadCollections();
}
status();
setInterval(status, 15000);
