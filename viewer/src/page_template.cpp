// page_template.cpp — style, markup and script of the viewer page (see trellis/viewer/view.hpp).
//
// The script only draws: body poses come sampled from the library's kinematics; between samples it
// interpolates (positions linearly, orientations by slerp). Hooks for tests and scripts, in the
// URL's fragment (file:///…/view.html#probe=0.5,1&frames=a,b):
//   probe=T1,T2,…   for every trajectory (or the state), the world position of every frame (or of
//                   those in frames=…) at each time, read from the scene graph, and every force
//                   arrow as drawn (its start and its direction × shaft length / scale), written
//                   as JSON into <pre id="trellis-probe">;
//   t=T             show time T, paused;
//   bare            hide the title, legend, warnings and controls (only the drawing);
//   bench=N         draw N frames of playback and report the time per frame in the status.
// <pre id="trellis-status"> holds {"ready": true, "errors": [...], "loadMs": …} once the first
// picture is complete (loadMs: from the navigation's start; marks.scriptStartMs: when this script
// began, after the markup and three.js); every JavaScript error of the page (also in three.js) is
// listed in "errors".
#include "page_template.hpp"

namespace trellis {

const char* const kViewerStyle = R"HTML(<style>
html, body { margin: 0; height: 100%; overflow: hidden; background: #f4f5f7;
  font: 13px/1.35 system-ui, -apple-system, "Segoe UI", sans-serif; color: #1d2733; }
#view { position: absolute; inset: 0; }
#title { position: absolute; left: 12px; top: 8px; font-weight: 600; font-size: 15px; pointer-events: none; }
#legend { position: absolute; right: 10px; top: 8px; background: rgba(255,255,255,0.85); padding: 6px 10px;
  border-radius: 6px; max-height: 60%; overflow-y: auto; }
#legend label { display: block; white-space: nowrap; }
#warnings { position: absolute; left: 12px; top: 34px; max-width: 60%; background: #fff4cc; padding: 4px 8px;
  border-radius: 4px; font-size: 12px; }
#panel { position: absolute; left: 0; right: 0; bottom: 0; display: flex; gap: 10px; align-items: center;
  padding: 8px 12px; background: rgba(255,255,255,0.9); border-top: 1px solid #d5dae0; }
#panel input[type=range] { flex: 1; }
#time { font-variant-numeric: tabular-nums; min-width: 11em; }
.swatch { display: inline-block; width: 10px; height: 10px; border-radius: 2px; margin-right: 4px; }
</style>
)HTML";

const char* const kViewerBody = R"HTML(<script>
// Installed before three.js: every error of the page is recorded for the status block.
window.trellisErrors = [];
window.addEventListener("error", function (e) {
  window.trellisErrors.push(String(e.message) + " (" + (e.filename || "page") + ":" + (e.lineno || 0) + ")");
  var s = document.getElementById("trellis-status");
  if (s) s.textContent = JSON.stringify({ready: false, errors: window.trellisErrors});
});
window.addEventListener("unhandledrejection", function (e) {
  window.trellisErrors.push("unhandled rejection: " + String(e.reason));
});
</script>
<div id="view"></div>
<div id="title"></div>
<div id="warnings" hidden></div>
<div id="legend"></div>
<div id="panel">
  <button id="play" type="button">Play</button>
  <input id="slider" type="range" min="0" max="10000" value="0">
  <span id="time"></span>
  <label>speed <select id="speed">
    <option value="0.1">0.1×</option><option value="0.25">0.25×</option><option value="0.5">0.5×</option>
    <option value="1" selected>1×</option><option value="2">2×</option></select></label>
  <label><input id="loop" type="checkbox" checked> loop</label>
</div>
<pre id="trellis-status" hidden>{"ready": false, "errors": []}</pre>
<pre id="trellis-probe" hidden></pre>
)HTML";

const char* const kViewerScript = R"JS((function () {
"use strict";
const t0 = performance.now();
const D = JSON.parse(document.getElementById("trellis-data").textContent);

// base64 → typed array: the browser's own decoder where it has one (Uint8Array.fromBase64), else atob.
function decode(text, Type) {
  let bytes;
  if (typeof Uint8Array.fromBase64 === "function") {
    bytes = Uint8Array.fromBase64(text);
  } else {
    const s = atob(text);
    bytes = new Uint8Array(s.length);
    for (let i = 0; i < s.length; ++i) bytes[i] = s.charCodeAt(i);
  }
  return new Type(bytes.buffer, bytes.byteOffset, bytes.byteLength / Type.BYTES_PER_ELEMENT);
}
function fragment() {
  const out = {};
  for (const part of location.hash.replace(/^#/, "").split("&")) {
    if (!part) continue;
    const eq = part.indexOf("=");
    out[decodeURIComponent(eq < 0 ? part : part.slice(0, eq))] = eq < 0 ? "" : decodeURIComponent(part.slice(eq + 1));
  }
  return out;
}

const marks = {scriptStartMs: t0, parseMs: performance.now() - t0};
const nb = D.bodies.length;
const state = decode(D.state, Float64Array);
// Poses: float64; float32 (ghosts); or delta32: float32 differences from the base trajectory's
// float64 poses at the same times, added back here in float64.
const trajectories = [];
for (const t of D.trajectories) {
  let poses;
  if (t.encoding === "delta32") {
    const delta = decode(t.poses, Float32Array), base = trajectories[t.base].poses;
    poses = new Float64Array(delta.length);
    for (let i = 0; i < delta.length; ++i) poses[i] = base[i] + delta[i];
  } else {
    poses = decode(t.poses, t.encoding === "float32" ? Float32Array : Float64Array);
  }
  trajectories.push({name: t.name, ghost: t.ghost, knots: t.knots, encoding: t.encoding, poses: poses,
                     t: "timesOf" in t ? trajectories[t.timesOf].t : decode(t.t, Float64Array),
                     tensions: t.tensions ? decode(t.tensions, Float64Array) : null, maxTension: t.maxTension || 0,
                     forces: t.forces ? decode(t.forces, Float64Array) : null});
}
const arrowGroups = D.arrows || [];
marks.decodeMs = performance.now() - t0 - marks.parseMs;
const R = D.view.radius;
const up = new THREE.Vector3().fromArray(D.view.up);
const centre = new THREE.Vector3().fromArray(D.view.centre);

// ---- renderer, camera, lights, ground ------------------------------------------------------------
const renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
renderer.setPixelRatio(window.devicePixelRatio || 1);
document.getElementById("view").appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f5f7);
const camera = new THREE.PerspectiveCamera(40, 1, R * 0.005, R * 200);
camera.up.copy(up);
// A side view: mostly along a horizontal axis (z when up is y: planar models in x-y face the camera).
const side = [new THREE.Vector3(0, 0, 1), new THREE.Vector3(1, 0, 0), new THREE.Vector3(0, 1, 0)]
  .find(function (v) { return Math.abs(v.dot(up)) < 0.9; }).clone();
side.addScaledVector(up, -side.dot(up)).normalize();
const across = new THREE.Vector3().crossVectors(up, side);
const eye = side.clone().multiplyScalar(0.8).addScaledVector(across, -0.45).addScaledVector(up, 0.45).normalize();
camera.position.copy(centre).addScaledVector(eye, 2.4 * R);
const controls = new THREE.OrbitControls(camera, renderer.domElement);
controls.target.copy(centre);
controls.update();
const hemisphere = new THREE.HemisphereLight(0xffffff, 0x8090a0, 0.85);
hemisphere.position.copy(up);
scene.add(hemisphere);
const sun = new THREE.DirectionalLight(0xffffff, 0.55);
sun.position.copy(centre).addScaledVector(eye, 4 * R).addScaledVector(up, 4 * R);
scene.add(sun);

const categories = {bodies: [], links: [], visuals: [], constraints: [], tendons: [], forces: [], ground: []};
const step = Math.pow(10, Math.floor(Math.log10(R)));
const gridSize = Math.ceil(3 * R / step) * 2 * step;
const grid = new THREE.GridHelper(gridSize, Math.round(gridSize / step), 0xaab3bd, 0xdde1e6);
grid.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), up);
grid.position.copy(centre).addScaledVector(up, D.view.floor - centre.dot(up));
scene.add(grid);
const axes = new THREE.AxesHelper(0.25 * R);
scene.add(axes);
categories.ground.push(grid, axes);

// ---- shared geometry and materials ---------------------------------------------------------------
const colours = {body: 0x2f6db5, link: 0x7d8ea3, visual: 0xaab4c2, constraint: 0xd0452f, tendon: 0x23955a, force: 0xc2188b};
function material(colour, ghost, extra) {
  const m = new THREE.MeshStandardMaterial(Object.assign({color: colour, roughness: 0.55, metalness: 0.05}, extra || {}));
  if (ghost) { m.transparent = true; m.opacity = 0.2; m.depthWrite = false; }
  return m;
}
function lineMaterial(colour, ghost) {
  return new THREE.LineBasicMaterial({color: colour, transparent: ghost, opacity: ghost ? 0.3 : 1});
}
let maxMass = 0;
for (const b of D.bodies) maxMass = Math.max(maxMass, b.mass);
const linkRadius = 0.012 * R;
const unitSphere = new THREE.SphereGeometry(1, 20, 14);
const unitCylinder = new THREE.CylinderGeometry(1, 1, 1, 14, 1, true);
// Force arrows: the shaft's length is the force times forceScale (the largest force over the page
// is a quarter of the scene's radius); the head has a fixed size.
const forceScale = D.largestForce > 0 ? 0.25 * R / D.largestForce : 0;
const arrowShaft = new THREE.CylinderGeometry(1, 1, 1, 10, 1, false).translate(0, 0.5, 0);
const arrowHead = new THREE.ConeGeometry(2.5, 6, 12).translate(0, 3, 0);
const visualGeometry = D.visuals.map(function (v) {
  let g;
  if (v.shape === "box" || v.shape === "standin") g = new THREE.BoxGeometry(Math.max(v.size[0], 1e-6), Math.max(v.size[1], 1e-6), Math.max(v.size[2], 1e-6));
  else if (v.shape === "cylinder") { g = new THREE.CylinderGeometry(v.size[0], v.size[0], v.size[1], 28); g.rotateX(Math.PI / 2); }
  else if (v.shape === "sphere") g = new THREE.SphereGeometry(v.size[0], 24, 16);
  else {
    g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(decode(D.meshes[v.mesh], Float32Array), 3));
    g.computeVertexNormals();
  }
  return g;
});

// The parent–child pairs drawn as capsules: those apart (more than 1e-4 R) in the state or at the
// first, middle or last sample of a trajectory (a revolute joint's frames coincide: no capsule).
function worldAt(poses, k, index) {
  const f = D.frames[index];
  const p = new THREE.Vector3(), q = new THREE.Quaternion();
  if (index < 0) return p;
  if (f.body >= 0) {
    const o = 7 * (k * nb + f.body);
    p.set(poses[o], poses[o + 1], poses[o + 2]);
    q.set(poses[o + 4], poses[o + 5], poses[o + 6], poses[o + 3]);
    if (f.p) p.add(new THREE.Vector3().fromArray(f.p).applyQuaternion(q));
  } else {
    p.fromArray(f.p);
  }
  return p;
}
const poseChecks = [[state, 0]];
for (const t of trajectories) {
  const last = t.t.length - 1;
  poseChecks.push([t.poses, 0], [t.poses, last >> 1], [t.poses, last]);
}
const linkPairs = [];
D.frames.forEach(function (f, i) {
  if (f.marker) return;  // a tendon via point or constraint point: its line shows it
  const apart = poseChecks.some(function (c) {
    return worldAt(c[0], c[1], i).distanceTo(worldAt(c[0], c[1], f.parent)) > 1e-4 * R;
  });
  if (apart) linkPairs.push([f.parent, i]);
});

// ---- one drawing per trajectory (or one for the state) -------------------------------------------
// Ghosts share their materials, and their parts (body spheres, capsules, visuals) are drawn as one
// InstancedMesh per geometry for all ghosts: a handful of draw calls instead of one per part and
// ghost (the hand's twenty closed loops: 900). setPoses writes each part's world matrix.
const ghostMats = {body: material(colours.body, true), link: material(colours.link, true),
                   visual: material(colours.visual, true), standin: material(0xe0a030, true, {wireframe: true})};
const ghostBatches = new Map();  // geometry and material → {geometry, material, category, items, mesh}
function ghostPart(inst, key, geometry, mat, category, place) {
  let batch = ghostBatches.get(key);
  if (!batch) {
    batch = {geometry: geometry, material: mat, category: category, items: [], mesh: null};
    ghostBatches.set(key, batch);
  }
  const item = {batch: batch, index: batch.items.length, place: place};
  batch.items.push(item);
  inst.parts.push(item);
  return item;
}
let instanceCount = 0;
function makeInstance(ghost, withArrows) {
  const inst = {group: new THREE.Group(), bodies: [], frames: [], links: [], lines: [], arrows: [], parts: []};
  scene.add(inst.group);
  const mats = ghost ? ghostMats : {body: material(colours.body, false), link: material(colours.link, false),
                                    visual: material(colours.visual, false),
                                    standin: material(0xe0a030, false, {wireframe: true})};
  for (let j = 0; j < nb; ++j) {
    const o = new THREE.Object3D();
    inst.group.add(o);
    inst.bodies.push(o);
  }
  D.frames.forEach(function (f, i) {
    let o;
    if (f.body >= 0 && D.bodies[f.body].frame === i) {
      o = inst.bodies[f.body];
    } else {
      o = new THREE.Object3D();
      o.position.fromArray(f.p);
      o.quaternion.set(f.q[1], f.q[2], f.q[3], f.q[0]);
      (f.body >= 0 ? inst.bodies[f.body] : inst.group).add(o);
    }
    inst.frames.push(o);
  });
  D.bodies.forEach(function (b, j) {
    if (!(b.mass > 0)) return;
    const r = Math.max(0.07 * R * Math.cbrt(b.mass / maxMass), 0.02 * R);
    if (ghost) {
      const local = new THREE.Matrix4().makeScale(r, r, r).setPosition(new THREE.Vector3().fromArray(b.com));
      const body = inst.bodies[j];
      ghostPart(inst, "body", unitSphere, mats.body, "bodies", function (m) { m.multiplyMatrices(body.matrixWorld, local); return true; });
      return;
    }
    const s = new THREE.Mesh(unitSphere, mats.body);
    s.scale.setScalar(r);
    s.position.fromArray(b.com);
    inst.bodies[j].add(s);
    categories.bodies.push(s);
  });
  const knuckle = new Set();
  for (const pair of linkPairs) {
    // Links between world-fixed frames do not move: drawn once, with the first trajectory.
    const fixed = (pair[0] < 0 || D.frames[pair[0]].body < 0) && D.frames[pair[1]].body < 0;
    if (fixed && instanceCount > 0) continue;
    if (ghost) {
      const link = {mesh: null, matrix: new THREE.Matrix4(), visible: false, a: pair[0], b: pair[1]};
      inst.links.push(link);
      ghostPart(inst, "link", unitCylinder, mats.link, "links", function (m) { m.copy(link.matrix); return link.visible; });
      continue;  // ghosts: capsules without joints
    }
    const m = new THREE.Mesh(unitCylinder, mats.link);
    inst.group.add(m);
    inst.links.push({mesh: m, a: pair[0], b: pair[1]});
    categories.links.push(m);
    for (const f of pair) {
      if (ghost || f < 0 || knuckle.has(f)) continue;  // ghosts: capsules without joints (fewer draws)
      knuckle.add(f);
      const k = new THREE.Mesh(unitSphere, mats.link);
      k.scale.setScalar(linkRadius);
      inst.frames[f].add(k);
      categories.links.push(k);
    }
  }
  D.visuals.forEach(function (v, i) {
    if (D.frames[v.f].body < 0 && instanceCount > 0) return;  // world-fixed: drawn once
    if (ghost) {
      const local = new THREE.Matrix4().compose(new THREE.Vector3().fromArray(v.p),
                                                new THREE.Quaternion(v.q[1], v.q[2], v.q[3], v.q[0]),
                                                v.shape === "mesh" ? new THREE.Vector3().fromArray(v.size) : new THREE.Vector3(1, 1, 1));
      const frame = inst.frames[v.f];
      ghostPart(inst, "visual" + i, visualGeometry[i], v.shape === "standin" ? mats.standin : mats.visual, "visuals",
                function (m) { m.multiplyMatrices(frame.matrixWorld, local); return true; });
      return;
    }
    const m = new THREE.Mesh(visualGeometry[i], v.shape === "standin" ? mats.standin : mats.visual);
    m.position.fromArray(v.p);
    m.quaternion.set(v.q[1], v.q[2], v.q[3], v.q[0]);
    if (v.shape === "mesh") m.scale.fromArray(v.size);
    inst.frames[v.f].add(m);
    categories.visuals.push(m);
  });
  function polyline(points, colour, category) {
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * points.length), 3));
    const line = new THREE.Line(g, lineMaterial(colour, ghost));
    line.frustumCulled = false;
    inst.group.add(line);
    inst.lines.push({line: line, points: points});
    categories[category].push(line);
  }
  ++instanceCount;
  if (!ghost) {  // ghosts show the bodies' motion; lines of twenty ghosts would hide the reference
    for (const c of D.constraints) polyline([c.a, c.b], colours.constraint, "constraints");
    for (const t of D.tendons) polyline(t.points, colours.tendon, "tendons");
  }
  if (withArrows) {
    const m = material(colours.force, false);
    const radius = 0.006 * R;
    for (const g of arrowGroups) {
      const arrow = new THREE.Group(), shaft = new THREE.Mesh(arrowShaft, m), head = new THREE.Mesh(arrowHead, m);
      shaft.scale.set(radius, 1, radius);
      head.scale.setScalar(radius);
      arrow.add(shaft, head);
      inst.group.add(arrow);
      inst.arrows.push({object: arrow, shaft: shaft, head: head, group: g});
      categories.forces.push(arrow);
    }
  }
  return inst;
}

const yAxis = new THREE.Vector3(0, 1, 0);
const pa = new THREE.Vector3(), pb = new THREE.Vector3(), qa = new THREE.Quaternion(), qb = new THREE.Quaternion();
const partMatrix = new THREE.Matrix4(), hidden = new THREE.Matrix4().makeScale(0, 0, 0);
const linkScale = new THREE.Vector3(), linkDirection = new THREE.Vector3(), linkRotation = new THREE.Quaternion();
function worldPosition(inst, f, out) {
  return f < 0 ? out.set(0, 0, 0) : out.setFromMatrixPosition(inst.frames[f].matrixWorld);
}
// Arrow a of a trajectory at samples k (and k + 1 with weight alpha): its point and force, linearly
// interpolated; hidden where the dynamics failed (NaN) or the force vanishes.
const fp = new THREE.Vector3(), ff = new THREE.Vector3(), fb = new THREE.Vector3();
function setArrows(inst, forces, k, alpha) {
  const na = arrowGroups.length;
  inst.arrows.forEach(function (a, g) {
    const o = 6 * (k * na + g);
    fp.set(forces[o], forces[o + 1], forces[o + 2]);
    ff.set(forces[o + 3], forces[o + 4], forces[o + 5]);
    if (alpha > 0) {
      const n = o + 6 * na;
      fp.lerp(fb.set(forces[n], forces[n + 1], forces[n + 2]), alpha);
      ff.lerp(fb.set(forces[n + 3], forces[n + 4], forces[n + 5]), alpha);
    }
    const length = ff.length() * forceScale;
    a.object.visible = toggles.forces && isFinite(length) && length > 0;
    a.valid = isFinite(length);
    if (!a.valid) return;
    a.object.position.copy(fp);
    if (length > 0) a.object.quaternion.setFromUnitVectors(yAxis, ff.divideScalar(ff.length()));
    a.shaft.scale.y = length;
    a.head.position.y = length;
  });
}
// Body poses at samples k (and k + 1 with weight alpha; alpha = 0 gives the sample exactly).
function setPoses(inst, poses, k, alpha) {
  for (let j = 0; j < nb; ++j) {
    const o = 7 * (k * nb + j);
    const body = inst.bodies[j];
    body.position.set(poses[o], poses[o + 1], poses[o + 2]);
    body.quaternion.set(poses[o + 4], poses[o + 5], poses[o + 6], poses[o + 3]);
    if (alpha > 0) {
      const n = o + 7 * nb;
      pb.set(poses[n], poses[n + 1], poses[n + 2]);
      body.position.lerp(pb, alpha);
      qb.set(poses[n + 4], poses[n + 5], poses[n + 6], poses[n + 3]);
      body.quaternion.slerp(qb, alpha);
    }
  }
  inst.group.updateMatrixWorld(true);
  for (const l of inst.links) {
    worldPosition(inst, l.a, pa);
    worldPosition(inst, l.b, pb);
    const length = pa.distanceTo(pb);
    const visible = length > 1e-9 * R && toggles.links;
    if (l.mesh) l.mesh.visible = visible; else l.visible = visible;
    if (!visible) continue;
    linkRotation.setFromUnitVectors(yAxis, linkDirection.subVectors(pb, pa).divideScalar(length));
    pa.add(pb).multiplyScalar(0.5);
    linkScale.set(linkRadius, length, linkRadius);
    if (l.mesh) {
      l.mesh.position.copy(pa);
      l.mesh.quaternion.copy(linkRotation);
      l.mesh.scale.copy(linkScale);
      l.mesh.updateMatrixWorld();
    } else {
      l.matrix.compose(pa, linkRotation, linkScale);
    }
  }
  // Ghost parts: their world matrices into the shared instanced meshes (hidden: scale 0).
  for (const item of inst.parts) {
    const shown = inst.group.visible && item.place(partMatrix);
    item.batch.mesh.setMatrixAt(item.index, shown ? partMatrix : hidden);
    item.batch.mesh.instanceMatrix.needsUpdate = true;
  }
  for (const l of inst.lines) {
    const a = l.line.geometry.attributes.position;
    l.points.forEach(function (p, i) {
      pa.fromArray(p.p);
      if (p.f >= 0) pa.applyMatrix4(inst.frames[p.f].matrixWorld);
      a.setXYZ(i, pa.x, pa.y, pa.z);
    });
    a.needsUpdate = true;
  }
}
// Largest sample index k with t[k] <= time, and the weight of k + 1.
function locate(t, time) {
  const last = t.length - 1;
  if (!(time > t[0])) return [0, 0];
  if (time >= t[last]) return [last, 0];
  let lo = 0, hi = last;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (t[mid] <= time) lo = mid; else hi = mid;
  }
  return [lo, (time - t[lo]) / (t[lo + 1] - t[lo])];
}

const toggles = {bodies: true, links: true, visuals: true, constraints: true, tendons: true, forces: true, ground: true};
const instances = [];
if (trajectories.length === 0) {
  instances.push({inst: makeInstance(false, false), poses: state, t: new Float64Array([0]), name: "state", shown: true});
} else {
  for (const tr of trajectories) {
    instances.push({inst: makeInstance(tr.ghost, tr.forces !== null), poses: tr.poses, t: tr.t, name: tr.name,
                    ghost: tr.ghost, encoding: tr.encoding, shown: true, tensions: tr.tensions, maxTension: tr.maxTension,
                    forces: tr.forces});
  }
}
for (const batch of ghostBatches.values()) {
  batch.mesh = new THREE.InstancedMesh(batch.geometry, batch.material, batch.items.length);
  batch.mesh.frustumCulled = false;  // its bounding sphere is the geometry's, not the instances'
  scene.add(batch.mesh);
  categories[batch.category].push(batch.mesh);
}
// Tendon colour by tension u / max u over the trajectory: pale green (slack) to dark green.
const slack = new THREE.Color(0xb9e4c9), taut = new THREE.Color(0x0a5c2e);
function colourTendons(i, k, alpha) {
  const nt = D.tendons.length, lines = i.inst.lines.slice(D.constraints.length);
  lines.forEach(function (l, j) {
    let u = i.tensions[k * nt + j];
    if (alpha > 0) u += alpha * (i.tensions[(k + 1) * nt + j] - u);
    const s = i.maxTension > 0 ? Math.min(Math.max(u / i.maxTension, 0), 1) : 0;
    l.line.material.color.copy(slack).lerp(taut, s);
  });
}
marks.buildMs = performance.now() - t0 - marks.parseMs - marks.decodeMs;
let tmin = Infinity, tmax = -Infinity;
for (const i of instances) { tmin = Math.min(tmin, i.t[0]); tmax = Math.max(tmax, i.t[i.t.length - 1]); }
let time = tmin;
function setTime(value) {
  time = Math.min(Math.max(value, tmin), tmax);
  for (const i of instances) {
    const [k, alpha] = locate(i.t, time);
    setPoses(i.inst, i.poses, k, alpha);
    if (i.tensions) colourTendons(i, k, alpha);
    if (i.forces) setArrows(i.inst, i.forces, k, alpha);
  }
}

// ---- page controls --------------------------------------------------------------------------------
document.getElementById("title").textContent = D.title;
if (D.warnings.length > 0) {
  const w = document.getElementById("warnings");
  w.hidden = false;
  w.textContent = D.warnings.join("\n");
}
const legend = document.getElementById("legend");
function addToggle(text, swatch, checked, onChange) {
  const label = document.createElement("label");
  const box = document.createElement("input");
  box.type = "checkbox";
  box.checked = checked;
  box.addEventListener("change", function () { onChange(box.checked); dirty = true; });
  label.appendChild(box);
  if (swatch !== null) {
    const s = document.createElement("span");
    s.className = "swatch";
    s.style.background = swatch;
    label.appendChild(s);
  }
  label.appendChild(document.createTextNode(text));
  legend.appendChild(label);
}
const ghosts = instances.filter(function (i) { return i.ghost; });
for (const i of instances) {
  if (i.ghost && ghosts.length > 4) continue;  // many ghosts: one switch for all (below)
  addToggle(i.name + (i.ghost ? " (ghost)" : ""), i.ghost ? "rgba(47,109,181,0.3)" : "#2f6db5", true,
            function (on) { i.inst.group.visible = on; setTime(time); });
}
if (ghosts.length > 4) {
  addToggle(ghosts.length + " ghosts (" + ghosts[0].name + " … " + ghosts[ghosts.length - 1].name + ")",
            "rgba(47,109,181,0.3)", true, function (on) { for (const i of ghosts) i.inst.group.visible = on; setTime(time); });
}
for (const name of Object.keys(toggles)) {
  if (categories[name].length === 0 && name !== "links") continue;
  let text = name;
  if (name === "forces") {
    // The scale: the shaft of the largest force is a quarter of the scene's radius.
    const metres = 0.25 * R, digits = function (x) { return Number(x.toPrecision(3)); };
    text = "constraint forces (arrow " + digits(100 * metres) + " cm = " + digits(D.largestForce) + " N)";
  }
  addToggle(text, name === "forces" ? "#c2188b" : null, true, function (on) {
    toggles[name] = on;
    for (const o of categories[name]) o.visible = on;
    setTime(time);
  });
}

const slider = document.getElementById("slider"), label = document.getElementById("time");
const playButton = document.getElementById("play"), speed = document.getElementById("speed");
const loop = document.getElementById("loop");
let playing = false, dirty = true, last = null;
function showTime() {
  label.textContent = "t = " + time.toFixed(3) + " s of [" + tmin.toFixed(3) + ", " + tmax.toFixed(3) + "]";
  slider.value = String(tmax > tmin ? Math.round(10000 * (time - tmin) / (tmax - tmin)) : 0);
}
function play(on) {
  playing = on && tmax > tmin;
  playButton.textContent = playing ? "Pause" : "Play";
  last = null;
}
playButton.addEventListener("click", function () { if (time >= tmax) setTime(tmin); play(!playing); });
slider.addEventListener("input", function () {
  play(false);
  setTime(tmin + (tmax - tmin) * Number(slider.value) / 10000);
  showTime();
  dirty = true;
});
controls.addEventListener("change", function () { dirty = true; });
function resize() {
  renderer.setSize(window.innerWidth, window.innerHeight);
  camera.aspect = window.innerWidth / Math.max(window.innerHeight, 1);
  camera.updateProjectionMatrix();
  dirty = true;
}
window.addEventListener("resize", resize);
resize();

function frame(now) {
  if (playing) {
    if (last !== null) {
      let next = time + (now - last) / 1000 * Number(speed.value);
      if (next > tmax) {
        if (loop.checked) next = tmin + (next - tmax) % Math.max(tmax - tmin, 1e-9);
        else { next = tmax; play(false); }
      }
      setTime(next);
      showTime();
      dirty = true;
    }
    last = now;
  }
  if (dirty) { renderer.render(scene, camera); dirty = false; }
  requestAnimationFrame(frame);
}

// ---- hooks for tests and scripts ------------------------------------------------------------------
const hash = fragment();
if ("probe" in hash) {
  const times = hash.probe.split(",").filter(function (s) { return s !== ""; }).map(Number);
  const wanted = "frames" in hash ? hash.frames.split(",") : D.frames.map(function (f) { return f.name; });
  const index = wanted.map(function (name) {
    const i = D.frames.findIndex(function (f) { return f.name === name; });
    if (i < 0) throw new Error("probe: no frame '" + name + "'");
    return i;
  });
  const result = {times: times, radius: R, trajectories: []};
  instances.forEach(function (i, n) {
    const stored = D.trajectories[n] || {};
    result.trajectories.push({name: i.name, ghost: !!i.ghost, encoding: i.encoding || "float64",
                              rounding: stored.rounding || 0, frames: {},
                              arrows: i.inst.arrows.map(function (a) { return {names: a.group.names, values: []}; })});
  });
  const axis = new THREE.Vector3();
  const p = new THREE.Vector3();
  for (const t of times) {
    setTime(t);
    instances.forEach(function (i, n) {
      index.forEach(function (f, w) {
        worldPosition(i.inst, f, p);
        (result.trajectories[n].frames[wanted[w]] = result.trajectories[n].frames[wanted[w]] || []).push([p.x, p.y, p.z]);
      });
      // Each arrow as drawn: where it starts, and its direction times its shaft's length over the
      // scale (null where the dynamics failed).
      i.inst.arrows.forEach(function (a, g) {
        let value = null;
        if (a.valid) {
          // (No scale when every force of the page vanishes: the arrows are then all zero.)
          axis.copy(yAxis).applyQuaternion(a.object.quaternion).multiplyScalar(forceScale > 0 ? a.shaft.scale.y / forceScale : 0);
          value = [a.object.position.x, a.object.position.y, a.object.position.z, axis.x, axis.y, axis.z];
        }
        result.trajectories[n].arrows[g].values.push(value);
      });
    });
  }
  document.getElementById("trellis-probe").textContent = JSON.stringify(result);
}
if ("bare" in hash) {
  for (const id of ["title", "legend", "panel", "warnings"]) document.getElementById(id).style.display = "none";
}
setTime("t" in hash ? Number(hash.t) : tmin);
showTime();
renderer.render(scene, camera);
// The first picture complete (the GPU, or the software renderer, waited for): the load time,
// counted from the navigation's start (performance.now()'s origin).
renderer.getContext().finish();
dirty = false;
const status = {ready: true, errors: window.trellisErrors, loadMs: performance.now(), scriptMs: performance.now() - t0,
                bodies: nb, frames: D.frames.length, trajectories: trajectories.length,
                samples: trajectories.reduce(function (s, t) { return s + t.t.length; }, 0),
                warnings: D.warnings.length, marks: marks, drawCalls: renderer.info.render.calls};
if ("bench" in hash) {
  // N frames of playback (every drawing posed and rendered, the GPU waited for): the cost per frame.
  const frames = Math.max(1, Number(hash.bench) || 120);
  const gl = renderer.getContext();
  const start = performance.now();
  for (let i = 0; i < frames; ++i) {
    setTime(tmin + (tmax - tmin) * i / frames);
    renderer.render(scene, camera);
    gl.finish();
  }
  status.benchFrames = frames;
  status.benchMsPerFrame = (performance.now() - start) / frames;
  status.drawCalls = renderer.info.render.calls;
  setTime("t" in hash ? Number(hash.t) : tmin);
  renderer.render(scene, camera);
}
document.getElementById("trellis-status").textContent = JSON.stringify(status);
if (!("t" in hash) && !("probe" in hash) && !("bench" in hash)) play(true);
requestAnimationFrame(frame);
window.trellisView = {setTime: setTime, instances: instances, scene: scene, camera: camera, renderer: renderer};
})();
)JS";

}  // namespace trellis
