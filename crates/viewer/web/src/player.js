// The 3D player: every loaded clip is a track (bones as instanced cylinders,
// joints as instanced spheres) on a ground plane with a 1 m grid, an orbit
// camera, one clock for all tracks (each shows its own frame at the shared
// time, so clips at 120 and 30 Hz stay in sync), side by side or overlaid.
// Frames arrive in pages of float32 positions; a track plays as far as its
// pages have arrived and waits (buffering) beyond that.

import * as THREE from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { binary, json } from "./api.js";

export const PAGE_FRAMES = 1024;
const COLORS = [0x3b7cff, 0xf08c00, 0x2f9e44, 0x9c36b5, 0x1098ad, 0xe8590c];
const OCCLUDED = new THREE.Color(0xb0b4bb);
const CONTACT = new THREE.Color(0x2fb344);
const SKATING = new THREE.Color(0xe03131);
const TARGET = new THREE.Color(0xd0309a);
// flags per frame and point, as the servers send them
const FLAG_OCCLUDED = 1;
const FLAG_CONTACT = 2;
const FLAG_SKATING = 4;

const UP = new THREE.Vector3(0, 1, 0);

/// One clip in the scene.
class Track {
  constructor(clip, meta, color) {
    this.clip = clip;
    this.meta = meta;
    this.color = new THREE.Color(color);
    this.frames = meta.frames;
    this.points = meta.points.length;
    this.positions = new Float32Array(this.frames * this.points * 3);
    this.pageDone = new Uint8Array(Math.ceil(this.frames / PAGE_FRAMES));
    this.loaded = 0; // frames available from the start
    this.flags = null;
    this.offset = new THREE.Vector3();
    this.bones = meta.points.map((p, i) => [p.parent, i]).filter(([p]) => p >= 0);
    this.group = new THREE.Group();
    const cylinder = new THREE.CylinderGeometry(1, 1, 1, 8, 1);
    cylinder.translate(0, 0.5, 0);
    this.boneMesh = new THREE.InstancedMesh(
      cylinder,
      new THREE.MeshStandardMaterial({ color: 0xffffff, roughness: 0.6 }),
      Math.max(this.bones.length, 1),
    );
    this.jointMesh = new THREE.InstancedMesh(
      new THREE.SphereGeometry(1, 12, 8),
      new THREE.MeshStandardMaterial({ color: 0xffffff, roughness: 0.4 }),
      this.points,
    );
    for (const mesh of [this.boneMesh, this.jointMesh]) {
      mesh.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
      mesh.frustumCulled = false;
      mesh.castShadow = true;
      this.group.add(mesh);
    }
    this.effector = meta.ik ? meta.ik.effector : -1;
    this.target = null;
    if (meta.ik && meta.ik.target) {
      this.target = new THREE.Mesh(
        new THREE.OctahedronGeometry(0.06),
        new THREE.MeshStandardMaterial({ color: TARGET, emissive: 0x400020 }),
      );
      this.group.add(this.target);
    }
    this.shownFrame = -1;
  }

  frameAt(time) {
    return Math.max(0, Math.min(this.frames - 1, Math.floor(time * this.meta.fps + 1e-6)));
  }

  duration() {
    return (this.frames - 1) / this.meta.fps;
  }

  /// Fetches the flags, then every page in order (three in flight).
  async load(onProgress) {
    const flagsUrl = this.clip.urls.flags;
    const flags = flagsUrl ? binary(flagsUrl).then((b) => (this.flags = new Uint8Array(b))) : null;
    const pages = this.pageDone.length;
    let next = 0;
    const worker = async () => {
      while (next < pages) {
        const page = next++;
        const start = page * PAGE_FRAMES;
        const count = Math.min(PAGE_FRAMES, this.frames - start);
        const sep = this.clip.urls.frames.includes("?") ? "&" : "?";
        const buffer = await binary(`${this.clip.urls.frames}${sep}start=${start}&count=${count}`);
        const data = new Float32Array(buffer);
        if (data.length !== count * this.points * 3) {
          throw new Error(`${this.clip.name}: page ${page} has ${data.length} values, expected ${count * this.points * 3}`);
        }
        this.positions.set(data, start * this.points * 3);
        this.pageDone[page] = 1;
        let k = Math.floor(this.loaded / PAGE_FRAMES);
        while (k < pages && this.pageDone[k]) k++;
        this.loaded = Math.min(this.frames, k * PAGE_FRAMES);
        onProgress();
      }
    };
    await Promise.all([worker(), worker(), worker()]);
    if (flags) await flags;
  }

  /// Poses the meshes at `frame` (already loaded).
  show(frame) {
    this.shownFrame = frame;
    const p = this.positions;
    const base = frame * this.points * 3;
    const m = new THREE.Matrix4();
    const q = new THREE.Quaternion();
    const s = new THREE.Vector3();
    const a = new THREE.Vector3();
    const b = new THREE.Vector3();
    const dir = new THREE.Vector3();
    const color = new THREE.Color();
    const flagsAt = (i) => (this.flags ? this.flags[frame * this.points + i] : 0);
    const nearKey = this.meta.ik && Math.abs(frame - this.meta.ik.keyframe) <= Math.max(2, Math.round(this.meta.fps / 15));
    this.bones.forEach(([parent, child], k) => {
      a.fromArray(p, base + parent * 3).add(this.offset);
      b.fromArray(p, base + child * 3).add(this.offset);
      dir.subVectors(b, a);
      const length = dir.length();
      q.setFromUnitVectors(UP, length > 1e-9 ? dir.divideScalar(length) : UP);
      s.set(0.014, Math.max(length, 1e-6), 0.014);
      m.compose(a, q, s);
      this.boneMesh.setMatrixAt(k, m);
      const hidden = (flagsAt(child) | flagsAt(parent)) & FLAG_OCCLUDED;
      this.boneMesh.setColorAt(k, hidden ? OCCLUDED : this.color);
    });
    q.identity();
    for (let i = 0; i < this.points; i++) {
      const f = flagsAt(i);
      a.fromArray(p, base + i * 3).add(this.offset);
      let r = this.meta.points[i].end ? 0.018 : 0.026;
      color.copy(this.color);
      if (f & FLAG_OCCLUDED) color.copy(OCCLUDED);
      if (f & FLAG_CONTACT) {
        color.copy(f & FLAG_SKATING ? SKATING : CONTACT);
        r = 0.04;
      }
      if (i === this.effector && nearKey) {
        color.copy(TARGET);
        r = 0.05;
      }
      s.setScalar(r);
      m.compose(a, q, s);
      this.jointMesh.setMatrixAt(i, m);
      this.jointMesh.setColorAt(i, color);
    }
    for (const mesh of [this.boneMesh, this.jointMesh]) {
      mesh.instanceMatrix.needsUpdate = true;
      if (mesh.instanceColor) mesh.instanceColor.needsUpdate = true;
    }
    if (this.target) {
      this.target.position.fromArray(this.meta.ik.target).add(this.offset);
    }
  }

  dispose() {
    this.group.traverse((o) => {
      if (o.geometry) o.geometry.dispose();
      if (o.material) o.material.dispose();
    });
  }
}

export class Player {
  constructor(stage, ui) {
    this.stage = stage;
    this.ui = ui;
    this.tracks = [];
    this.time = 0;
    this.playing = false;
    this.speed = 1;
    this.overlay = false;
    this.rendered = 0; // frames drawn since the page opened
    this.fps = 0;
    this.generation = 0;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: false });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.shadowMap.enabled = true;
    stage.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0xdfe3ea);
    this.scene.fog = new THREE.Fog(0xdfe3ea, 30, 90);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.05, 500);
    this.camera.position.set(3, 2, 4);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(0, 0.9, 0);
    this.controls.addEventListener("change", () => (this.dirty = true));
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8d8d8d, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.8);
    sun.position.set(4, 8, 3);
    sun.castShadow = true;
    sun.shadow.camera.left = sun.shadow.camera.bottom = -6;
    sun.shadow.camera.right = sun.shadow.camera.top = 6;
    this.sun = sun;
    this.scene.add(sun, sun.target);
    const ground = new THREE.Mesh(
      new THREE.PlaneGeometry(400, 400),
      new THREE.MeshStandardMaterial({ color: 0xf7f7f5, roughness: 1 }),
    );
    ground.rotation.x = -Math.PI / 2;
    ground.receiveShadow = true;
    this.scene.add(ground);
    const grid = new THREE.GridHelper(200, 200, 0x7d8590, 0xaab0b9);
    grid.position.y = 0.001;
    this.scene.add(grid);
    this.dirty = true;
    new ResizeObserver(() => this.resize()).observe(stage);
    this.resize();
    this.last = performance.now();
    this.fpsWindow = { start: this.last, frames: 0 };
    const loop = (now) => {
      this.tick(now);
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  resize() {
    const w = this.stage.clientWidth || 640;
    const h = this.stage.clientHeight || 360;
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.dirty = true;
  }

  duration() {
    return this.tracks.reduce((d, t) => Math.max(d, t.duration()), 0);
  }

  /// Replaces the tracks by `clips` (descriptors from the server), loading each.
  async open(clips) {
    const generation = ++this.generation;
    for (const t of this.tracks) {
      this.scene.remove(t.group);
      t.dispose();
    }
    this.tracks = [];
    this.time = 0;
    this.ui.onTracks([]);
    const metas = await Promise.all(clips.map((c) => json(c.urls.meta)));
    if (generation !== this.generation) return;
    this.tracks = clips.map((c, i) => new Track(c, metas[i], COLORS[i % COLORS.length]));
    for (const t of this.tracks) this.scene.add(t.group);
    this.layout();
    this.frameCamera();
    this.ui.onTracks(this.tracks);
    this.dirty = true;
    const started = performance.now();
    await Promise.all(this.tracks.map((t) => t.load(() => {
      this.dirty = true;
      this.ui.onProgress(this.tracks);
    })));
    if (generation !== this.generation) return;
    this.loadSeconds = (performance.now() - started) / 1000;
    this.ui.onLoaded(this.tracks, this.loadSeconds);
  }

  setOverlay(on) {
    this.overlay = on;
    this.layout();
    this.frameCamera();
    this.dirty = true;
  }

  /// Side by side: tracks apart along the horizontal axis their motion spans
  /// least, by their widest extent on it plus a margin; overlay: no offsets.
  layout() {
    const n = this.tracks.length;
    if (n === 0) return;
    const union = this.bounds(false);
    const axis = union.max[0] - union.min[0] <= union.max[2] - union.min[2] ? 0 : 2;
    const width = Math.max(...this.tracks.map((t) => t.meta.bounds.max[axis] - t.meta.bounds.min[axis]));
    const spacing = this.overlay ? 0 : Math.max(width, 0.4) + 0.6;
    this.tracks.forEach((t, i) => {
      t.offset.set(0, 0, 0);
      t.offset.setComponent(axis, (i - (n - 1) / 2) * spacing);
      t.shownFrame = -1;
    });
  }

  bounds(withOffsets = true) {
    const min = [Infinity, Infinity, Infinity];
    const max = [-Infinity, -Infinity, -Infinity];
    for (const t of this.tracks) {
      for (let k = 0; k < 3; k++) {
        const o = withOffsets ? t.offset.getComponent(k) : 0;
        min[k] = Math.min(min[k], t.meta.bounds.min[k] + o);
        max[k] = Math.max(max[k], t.meta.bounds.max[k] + o);
      }
    }
    return { min, max };
  }

  /// Looks at the clips from the side their layout spreads along (so side by
  /// side clips are next to each other), from far enough to see every point.
  frameCamera() {
    if (!this.tracks.length) return;
    const { min, max } = this.bounds();
    const centre = new THREE.Vector3((min[0] + max[0]) / 2, (min[1] + max[1]) / 2, (min[2] + max[2]) / 2);
    const extent = new THREE.Vector3(max[0] - min[0], max[1] - min[1], max[2] - min[2]);
    // View along the horizontal axis the clips span least.
    const alongX = extent.x <= extent.z;
    const view = alongX ? new THREE.Vector3(1, 0.45, 0.35) : new THREE.Vector3(0.35, 0.45, 1);
    view.normalize();
    const width = Math.max(alongX ? extent.z : extent.x, 1.2);
    const height = Math.max(extent.y, 1.8);
    const fov = (this.camera.fov * Math.PI) / 180;
    const fitHeight = height / 2 / Math.tan(fov / 2);
    const fitWidth = width / 2 / Math.tan(fov / 2) / this.camera.aspect;
    let distance = Math.max(fitHeight, fitWidth) + (alongX ? extent.x : extent.z) / 2;
    this.controls.target.copy(centre);
    // Back off until every corner of the box is well inside the picture.
    const corners = [];
    for (const x of [min[0], max[0]]) for (const y of [min[1], max[1]]) for (const z of [min[2], max[2]]) corners.push(new THREE.Vector3(x, y, z));
    for (let i = 0; i < 30; i++) {
      this.camera.position.copy(centre).addScaledVector(view, distance);
      this.camera.lookAt(centre);
      this.camera.updateMatrixWorld();
      const inside = corners.every((c) => {
        const p = c.clone().project(this.camera);
        return Math.abs(p.x) < 0.9 && Math.abs(p.y) < 0.85 && p.z < 1;
      });
      if (inside) break;
      distance *= 1.12;
    }
    const size = Math.max(extent.x, extent.y, extent.z, 1.5);
    this.camera.far = Math.max(500, size * 20);
    this.scene.fog.near = distance * 3;
    this.scene.fog.far = distance * 9;
    this.camera.updateProjectionMatrix();
    this.sun.target.position.copy(centre);
    this.sun.position.copy(centre).add(new THREE.Vector3(4, 8, 3));
    const half = Math.max(6, size);
    this.sun.shadow.camera.left = this.sun.shadow.camera.bottom = -half;
    this.sun.shadow.camera.right = this.sun.shadow.camera.top = half;
    this.sun.shadow.camera.updateProjectionMatrix();
    this.controls.update();
  }

  seek(time) {
    this.time = Math.max(0, Math.min(this.duration(), time));
    this.dirty = true;
  }

  /// Whether every track has the frame it needs at `time`.
  available(time) {
    return this.tracks.every((t) => t.frameAt(time) < t.loaded);
  }

  tick(now) {
    const dt = Math.min((now - this.last) / 1000, 0.25);
    this.last = now;
    let buffering = false;
    if (this.playing && this.tracks.length) {
      // Loops: past the end, playback carries on from the start by the
      // time it overshot (not from 0, which would stall a frame).
      const duration = this.duration();
      let next = this.time + dt * this.speed;
      if (next > duration) next = duration > 0 ? next % duration : 0;
      if (this.available(next)) {
        this.time = next;
      } else {
        buffering = true;
      }
      this.dirty = true;
    }
    if (this.dirty) {
      const posing = performance.now();
      for (const t of this.tracks) {
        const f = t.frameAt(this.time);
        if (f < t.loaded && f !== t.shownFrame) t.show(f);
        t.group.visible = t.shownFrame >= 0;
      }
      const rendering = performance.now();
      this.renderer.render(this.scene, this.camera);
      // Milliseconds per drawn frame (moving averages): posing the
      // skeletons from the frame data, and handing the scene to WebGL.
      const done = performance.now();
      this.poseMs = 0.9 * (this.poseMs || 0) + 0.1 * (rendering - posing);
      this.renderMs = 0.9 * (this.renderMs || 0) + 0.1 * (done - rendering);
      this.rendered++;
      this.fpsWindow.frames++;
      this.dirty = false;
      this.ui.onTime(this.time, this.tracks, buffering);
    }
    if (now - this.fpsWindow.start >= 1000) {
      this.fps = (this.fpsWindow.frames * 1000) / (now - this.fpsWindow.start);
      this.fpsWindow = { start: now, frames: 0 };
      this.ui.onFps(this.playing ? this.fps : null);
    }
  }
}
