// The gait, moving: a trial's recorded motion (worker/tools/motion.py's JSON) played in 3D with three.js.
// Rods are cylinders posed with their body, strings are lines coloured by tension (blue low, red high),
// the centre of mass leaves a trail over the ground. One Player drives any number of views in step.
import * as THREE from "three";
import {OrbitControls} from "/static/vendor/three/OrbitControls.js";

const ROD_COLOUR = 0x2b2b2b;
const GROUND_COLOUR = 0xe4dfd2;
const TRAIL_COLOUR = 0x2e9e5b;
const MIN_ROD_RADIUS_CM = 0.35;
// coolwarm, as the gait pictures: blue (no tension), grey, red (the run's peak)
const COOLWARM = [[0.23, 0.30, 0.75], [0.87, 0.87, 0.87], [0.71, 0.02, 0.15]];

function tensionColour(f, out, k) {
  const x = Math.min(1, Math.max(0, f)) * 2;
  const i = Math.min(1, Math.floor(x));
  const u = x - i;
  for (let c = 0; c < 3; c++) out[k + c] = COOLWARM[i][c] * (1 - u) + COOLWARM[i + 1][c] * u;
}

/** The frame shown at time t: the last recorded frame at or before t. */
export function frameAt(times, t) {
  let lo = 0, hi = times.length - 1;
  if (t <= times[0]) return 0;
  if (t >= times[hi]) return hi;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (times[mid] <= t) lo = mid; else hi = mid;
  }
  return lo;
}

export class MotionView {
  constructor(container, motion) {
    this.container = container;
    this.m = motion;
    this.frame = -1;
    this.follow = true;
    const w = Math.max(200, container.clientWidth), h = Math.max(200, container.clientHeight);
    this.renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.setSize(w, h);
    this.renderer.setClearColor(0xf7f8fa);
    container.replaceChildren(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8373, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(40, 120, 60);
    this.scene.add(sun);
    this._buildBodies();
    this._buildStrings();
    this._buildGroundAndTrail();
    const com = this.m.com_cm[0];
    this.camera = new THREE.PerspectiveCamera(40, w / h, 0.5, 20000);
    const size = this._robotSize();
    this.camera.position.set(com[0] + 0.55 * size, com[1] + 0.4 * size, com[2] + 0.6 * size);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.target.set(com[0], com[1], com[2]);
    this.controls.addEventListener("change", () => this.render());
    this.controls.update();
    this.lastCom = new THREE.Vector3(...com);
    this.resizer = new ResizeObserver(() => this._resize());
    this.resizer.observe(container);
    container.motionView = this;
  }

  _robotSize() {
    const p = this.m.poses[0], n = this.m.n_bodies;
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let b = 0; b < n; b++) for (let c = 0; c < 3; c++) {
      lo[c] = Math.min(lo[c], p[7 * b + c]); hi[c] = Math.max(hi[c], p[7 * b + c]);
    }
    return Math.max(30, hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  }

  _buildBodies() {
    this.bodies = [];
    for (let b = 0; b < this.m.n_bodies; b++) {
      const g = new THREE.Group();
      g.matrixAutoUpdate = true;
      this.scene.add(g);
      this.bodies.push(g);
    }
    const mat = new THREE.MeshStandardMaterial({color: ROD_COLOUR, roughness: 0.6, metalness: 0.1});
    this.rods = this.m.rods.map((rod) => {
      const a = new THREE.Vector3(...rod.a_cm), b = new THREE.Vector3(...rod.b_cm);
      const r = Math.max(MIN_ROD_RADIUS_CM, rod.radius_cm);
      const mesh = new THREE.Mesh(new THREE.CylinderGeometry(r, r, 1, 10), mat);
      mesh.position.copy(a).add(b).multiplyScalar(0.5);
      mesh.scale.set(1, a.distanceTo(b), 1);
      mesh.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), b.clone().sub(a).normalize());
      this.bodies[rod.body].add(mesh);
      return mesh;
    });
  }

  _buildStrings() {
    const n = this.m.strings.length;
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(6 * n), 3));
    geo.setAttribute("color", new THREE.BufferAttribute(new Float32Array(6 * n), 3));
    this.strings = new THREE.LineSegments(geo, new THREE.LineBasicMaterial({vertexColors: true}));
    this.strings.frustumCulled = false;
    this.scene.add(this.strings);
    this.anchors = this.m.strings.map((s) => [s.body_a, new THREE.Vector3(...s.anchor_a_cm),
      s.body_b, new THREE.Vector3(...s.anchor_b_cm)]);
  }

  _buildGroundAndTrail() {
    const com = this.m.com_cm, y = this.m.ground_top_cm;
    let lo = [Infinity, Infinity], hi = [-Infinity, -Infinity];
    for (const c of com) {
      lo = [Math.min(lo[0], c[0]), Math.min(lo[1], c[2])]; hi = [Math.max(hi[0], c[0]), Math.max(hi[1], c[2])];
    }
    const span = Math.max(hi[0] - lo[0], hi[1] - lo[1]) + 6 * this._robotSize();
    const step = 10 ** Math.floor(Math.log10(span / 10));
    const side = Math.ceil(span / step) * step;
    const ground = new THREE.Mesh(new THREE.PlaneGeometry(side, side),
      new THREE.MeshStandardMaterial({color: GROUND_COLOUR, roughness: 1}));
    ground.rotation.x = -Math.PI / 2;
    ground.position.set((lo[0] + hi[0]) / 2, y - 0.05, (lo[1] + hi[1]) / 2);
    this.scene.add(ground);
    const grid = new THREE.GridHelper(side, Math.round(side / step), 0xb9b2a0, 0xcfc9b9);
    grid.position.set(ground.position.x, y, ground.position.z);
    this.scene.add(grid);
    const pts = new Float32Array(3 * com.length);
    com.forEach((c, i) => { pts[3 * i] = c[0]; pts[3 * i + 1] = y + 0.1; pts[3 * i + 2] = c[2]; });
    const geo = new THREE.BufferGeometry();
    geo.setAttribute("position", new THREE.BufferAttribute(pts, 3));
    this.trail = new THREE.Line(geo, new THREE.LineBasicMaterial({color: TRAIL_COLOUR}));
    this.trail.frustumCulled = false;
    this.scene.add(this.trail);
    this.comMarker = new THREE.Mesh(new THREE.SphereGeometry(0.8, 12, 8),
      new THREE.MeshStandardMaterial({color: TRAIL_COLOUR}));
    this.scene.add(this.comMarker);
  }

  get duration() { return this.m.time_s[this.m.time_s.length - 1]; }

  /** Show the frame recorded at or before t (seconds). */
  setTime(t) {
    const i = frameAt(this.m.time_s, t);
    if (i !== this.frame) this.setFrame(i);
  }

  setFrame(i) {
    this.frame = i;
    const p = this.m.poses[i];
    this.bodies.forEach((g, b) => {
      g.position.set(p[7 * b], p[7 * b + 1], p[7 * b + 2]);
      g.quaternion.set(p[7 * b + 3], p[7 * b + 4], p[7 * b + 5], p[7 * b + 6]);
      g.updateMatrixWorld(true);
    });
    const pos = this.strings.geometry.attributes.position, col = this.strings.geometry.attributes.color;
    const tension = this.m.tension_n[i], tmax = this.m.tension_max_n > 0 ? this.m.tension_max_n : 1;
    const v = new THREE.Vector3();
    this.anchors.forEach(([ba, aa, bb, ab], s) => {
      v.copy(aa).applyMatrix4(this.bodies[ba].matrixWorld); pos.array.set([v.x, v.y, v.z], 6 * s);
      v.copy(ab).applyMatrix4(this.bodies[bb].matrixWorld); pos.array.set([v.x, v.y, v.z], 6 * s + 3);
      tensionColour(tension[s] / tmax, col.array, 6 * s);
      tensionColour(tension[s] / tmax, col.array, 6 * s + 3);
    });
    pos.needsUpdate = true; col.needsUpdate = true;
    const c = this.m.com_cm[i];
    this.comMarker.position.set(c[0], c[1], c[2]);
    this.trail.geometry.setDrawRange(0, i + 1);
    if (this.follow) {
      const now = new THREE.Vector3(c[0], c[1], c[2]);
      const d = now.clone().sub(this.lastCom);
      this.camera.position.add(d);
      this.controls.target.add(d);
      this.controls.update();
      this.lastCom.copy(now);
    }
    this.container.dataset.frame = String(i);
    this.container.dataset.time = String(this.m.time_s[i]);
    this.render();
  }

  /** World end points of every rod as drawn now: (n_rods) [ax, ay, az, bx, by, bz] in cm. */
  rodEnds() {
    return this.rods.map((mesh) => {
      mesh.updateWorldMatrix(true, false);
      const a = new THREE.Vector3(0, -0.5, 0).applyMatrix4(mesh.matrixWorld);
      const b = new THREE.Vector3(0, 0.5, 0).applyMatrix4(mesh.matrixWorld);
      return [a.x, a.y, a.z, b.x, b.y, b.z];
    });
  }

  /** World anchor points of every string as drawn now: (n_strings) [ax, ay, az, bx, by, bz] in cm. */
  stringEnds() {
    const a = this.strings.geometry.attributes.position.array;
    return this.m.strings.map((_, s) => Array.from(a.slice(6 * s, 6 * s + 6)));
  }

  render() { this.renderer.render(this.scene, this.camera); }

  _resize() {
    const w = this.container.clientWidth, h = this.container.clientHeight;
    if (w < 10 || h < 10) return;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  dispose() {
    this.resizer.disconnect();
    this.controls.dispose();
    this.renderer.dispose();
  }
}

/** One clock for any number of views: play/pause, a time slider, speed; views stay in step. */
export class Player {
  constructor(views, bar) {
    this.views = views;
    this.t = 0;
    this.speed = 1;
    this.playing = false;
    this.duration = Math.max(...views.map((v) => v.duration));
    this.bar = bar;
    bar.innerHTML = `<button id="motion-play" class="button" type="button">▶ play</button>
      <input id="motion-slider" type="range" min="0" max="1000" value="0" step="1">
      <span id="motion-time" class="muted"></span>
      <label>speed <select id="motion-speed">${[0.1, 0.25, 0.5, 1, 2, 4].map((s) =>
        `<option value="${s}"${s === 1 ? " selected" : ""}>${s}×</option>`).join("")}</select></label>
      <label><input id="motion-follow" type="checkbox" checked> follow</label>`;
    this.button = bar.querySelector("#motion-play");
    this.slider = bar.querySelector("#motion-slider");
    this.label = bar.querySelector("#motion-time");
    this.button.onclick = () => (this.playing ? this.pause() : this.play());
    this.slider.oninput = () => this.seek(this.slider.value / 1000 * this.duration);
    bar.querySelector("#motion-speed").onchange = (e) => { this.speed = Number(e.target.value); };
    bar.querySelector("#motion-follow").onchange = (e) => views.forEach((v) => { v.follow = e.target.checked; });
    this._tick = this._tick.bind(this);
    this.seek(0);
  }

  play() {
    if (this.t >= this.duration) this.t = 0;
    this.playing = true;
    this.button.textContent = "❚❚ pause";
    this.bar.dataset.playing = "1";
    this.last = performance.now();
    requestAnimationFrame(this._tick);
  }

  pause() {
    this.playing = false;
    this.button.textContent = "▶ play";
    this.bar.dataset.playing = "0";
  }

  seek(t) {
    this.t = Math.min(this.duration, Math.max(0, t));
    this.views.forEach((v) => v.setTime(this.t));
    this.slider.value = String(Math.round(1000 * this.t / Math.max(this.duration, 1e-9)));
    this.label.textContent = `${this.t.toFixed(2)} / ${this.duration.toFixed(2)} s`;
    this.bar.dataset.time = String(this.t);
  }

  _tick(now) {
    if (!this.playing || !this.views[0].container.isConnected) return;
    const dt = (now - this.last) / 1000;
    this.last = now;
    let t = this.t + dt * this.speed;
    if (t > this.duration) t = 0;  // loop
    this.seek(t);
    requestAnimationFrame(this._tick);
  }
}
