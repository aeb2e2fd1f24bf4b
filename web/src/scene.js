// The 3D view: ground with contact shadows, the horse and rider (skinned meshes, or the
// primitive sticks with ?render=sticks), tack, tail, braid and cloth flaps; camera presets and a
// camera that follows the horse or stays fixed. three.js is right-handed, +y up;
// riderlive's skeleton axes are +x forward, +y up, +z right, so no conversion.

import {
  CanvasTexture,
  Color,
  DirectionalLight,
  HemisphereLight,
  LinearMipmapNearestFilter,
  Mesh,
  MeshBasicMaterial,
  PerspectiveCamera,
  PlaneGeometry,
  RepeatWrapping,
  Scene,
  ShaderMaterial,
  Vector3,
  WebGLRenderer,
} from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { Bodies } from "./bodies.js";
import { qmul, rotate } from "./rig.js";
import { Sticks } from "./sticks.js";
import { Tack } from "./tack.js";
import { restingTail, tailStrands, Tubes } from "./tail.js";

/** Camera presets: about the horse when the camera follows, about the track's middle when fixed. */
export const VIEWS = {
  perspective: { pos: [3.4, 2.3, -3.4], target: [0.05, 1.2, 0], label: "¾ front" },
  side: { pos: [0.1, 1.35, -5.2], target: [0.1, 1.2, 0], label: "Side" },
  front: { pos: [5.2, 1.6, 0.0], target: [0, 1.2, 0], label: "Front" },
  rear: { pos: [-4.8, 2.0, 1.2], target: [0, 1.2, 0], label: "Rear" },
  rider: { pos: [1.7, 2.5, -2.3], target: [0.05, 1.95, 0], label: "Rider" },
  top: { pos: [0.0, 6.5, -0.01], target: [0, 1.0, 0], label: "Top" },
};
export const DEFAULT_VIEW = "perspective";
/** A fixed camera sees the horse come round every WRAP metres of travel. */
export const WRAP = 24;
const SEGMENT = 0.07;

const toLinear = (c) => (c <= 0.04045 ? c / 12.92 : ((c + 0.055) / 1.055) ** 2.4);
const toSRGB = (c) => (c <= 0.0031308 ? c * 12.92 : 1.055 * c ** (1 / 2.4) - 0.055);

/** The dirt texture (2 m square), lit by `light` (linear RGB per unit albedo) and sRGB-encoded: drawn as is. */
function groundTexture(light) {
  const c = document.createElement("canvas");
  c.width = c.height = 256;
  const g = c.getContext("2d");
  g.fillStyle = "#6f6250";
  g.fillRect(0, 0, 256, 256);
  let seed = 7;
  const rnd = () => ((seed = (seed * 16807) % 2147483647) / 2147483647);
  for (let i = 0; i < 2500; i++) {
    const v = 90 + rnd() * 40;
    g.fillStyle = `rgba(${v + 20},${v + 8},${v - 10},0.35)`;
    g.fillRect(rnd() * 256, rnd() * 256, 2, 2);
  }
  g.fillStyle = "rgba(40,32,24,0.5)"; // a line every metre (the texture is 2 m)
  g.fillRect(0, 0, 256, 2);
  g.fillRect(0, 128, 256, 2);
  const img = g.getImageData(0, 0, 256, 256);
  const lut = [light.r, light.g, light.b].map((k) => Uint8Array.from({ length: 256 }, (_, v) => Math.round(255 * toSRGB(Math.min(1, k * toLinear(v / 255))))));
  for (let i = 0; i < img.data.length; i += 4) for (let k = 0; k < 3; k++) img.data[i + k] = lut[k][img.data[i + k]];
  g.putImageData(img, 0, 0);
  const t = new CanvasTexture(c);
  t.wrapS = t.wrapT = RepeatWrapping;
  t.minFilter = LinearMipmapNearestFilter; // one mip level per pixel: half the texture reads of trilinear
  return t;
}

/**
 * The ground's material: the lit, sRGB-encoded texture drawn as is. A flat, unshadowed
 * ground's lighting is one colour (baked into the texture, see flatLight), and skipping the
 * lighting and the per-pixel sRGB encoding halves what the ground costs a software
 * rasteriser (SwiftShader), the page's largest single cost there (docs/performance.md).
 */
function groundMaterial(tex) {
  return new ShaderMaterial({
    uniforms: { map: { value: tex }, uvTransform: { value: tex.matrix } },
    vertexShader: `uniform mat3 uvTransform; varying vec2 vUv;
      void main() { vUv = (uvTransform * vec3(uv, 1.0)).xy; gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }`,
    fragmentShader: `uniform sampler2D map; varying vec2 vUv;
      void main() { gl_FragColor = vec4(texture2D(map, vUv).rgb, 1.0); }`,
  });
}

function blobTexture() {
  const c = document.createElement("canvas");
  c.width = c.height = 64;
  const g = c.getContext("2d");
  const grad = g.createRadialGradient(32, 32, 0, 32, 32, 32);
  grad.addColorStop(0, "rgba(0,0,0,1)");
  grad.addColorStop(1, "rgba(0,0,0,0)");
  g.fillStyle = grad;
  g.fillRect(0, 0, 64, 64);
  return new CanvasTexture(c);
}

/** Soft dark ellipses on the ground under the body and each hoof, fading as they rise. */
class ContactShadows {
  constructor(scene, count) {
    const tex = blobTexture();
    const plane = new PlaneGeometry(1, 1).rotateX(-Math.PI / 2);
    this.blobs = Array.from({ length: count }, () => {
      const m = new Mesh(plane, new MeshBasicMaterial({ map: tex, transparent: true, depthWrite: false, opacity: 0.5 }));
      m.renderOrder = 1;
      scene.add(m);
      return m;
    });
  }

  /** `spots`: [x, height above ground, z, size (m), strength 0..1]. */
  update(spots) {
    this.blobs.forEach((m, i) => {
      const s = spots[i];
      m.visible = Boolean(s);
      if (!s) return;
      const [x, h, z, size, strength] = s;
      const lift = Math.max(0, h);
      m.position.set(x, 0.003 + i * 1e-4, z);
      const grow = size * (1 + 1.5 * lift);
      m.scale.set(grow * (s[5] || 1), 1, grow);
      m.material.opacity = strength * Math.max(0, 1 - lift / 1.2);
    });
  }
}

/**
 * The colour a Lambert surface facing `normal` (unit, world) reflects per unit albedo
 * under the hemisphere light `sky` and the directional light `sun` (no shadows), in the
 * working (linear) colour space: (hemisphere + sun * cos) / pi, as three.js' Lambert does.
 */
export function flatLight(sky, sun, normal) {
  const up = 0.5 * (normal[0] * sky.position.x + normal[1] * sky.position.y + normal[2] * sky.position.z) / sky.position.length() + 0.5;
  const hemi = sky.groundColor.clone().lerp(sky.color, up).multiplyScalar(sky.intensity);
  const d = sun.position.clone().sub(sun.target.position).normalize();
  const cos = Math.max(0, normal[0] * d.x + normal[1] * d.y + normal[2] * d.z);
  return hemi.add(sun.color.clone().multiplyScalar(sun.intensity * cos)).multiplyScalar(1 / Math.PI);
}

export class View {
  constructor(canvas, horseRig, riderRig, { render = "mesh" } = {}) {
    this.canvas = canvas;
    this.render = render;
    this.renderer = new WebGLRenderer({ canvas, antialias: false, powerPreference: "low-power" });
    this.renderer.setPixelRatio(1);
    this.scene = new Scene();
    this.scene.background = new Color(0x1d2228);
    this.camera = new PerspectiveCamera(40, 1, 0.05, 120);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.enableDamping = false;
    const sky = new HemisphereLight(0xdfe8ff, 0x4a3c2c, 1.6);
    this.scene.add(sky);
    const sun = new DirectionalLight(0xffffff, 1.7);
    sun.position.set(2, 6, -3);
    this.scene.add(sun);
    this.groundTex = groundTexture(flatLight(sky, sun, [0, 1, 0]));
    this.groundTex.repeat.set(40, 40);
    this.groundTex.updateMatrix();
    const ground = new Mesh(new PlaneGeometry(80, 80).rotateX(-Math.PI / 2), groundMaterial(this.groundTex));
    this.scene.add(ground);
    this.ground = ground;
    this.shadows = new ContactShadows(this.scene, 6);
    this.horseRig = horseRig;
    this.riderRig = riderRig;
    if (render === "sticks") this.sticks = new Sticks(this.scene, horseRig, riderRig);
    else this.bodies = new Bodies(this.scene, horseRig, riderRig, { sky, sun });
    this.tack = render === "sticks" ? null : new Tack(this.scene, horseRig, riderRig);
    this.tail = new Tubes(this.scene, 4, 12, 0x1c1511, (s, t) => (s === 0 ? 0.035 + 0.03 * Math.sin(Math.PI * Math.min(1, t * 1.2)) : 0.018 * (1 - 0.6 * t)));
    this.braid = new Tubes(this.scene, 1, 10, 0x6b4a2a, (s, t) => 0.018 * (1 - 0.5 * t));
    // The rider's coat-skirt flaps (lf_cloth_NN, rt_cloth_NN): flattened to tubes, widening toward the hem.
    this.cloth = new Tubes(this.scene, 2, 12, 0x2b3a55, (s, t) => 0.03 + 0.03 * t);
    this.follow = true;
    this.setView(DEFAULT_VIEW);
    // The canvas' CSS size, kept by a ResizeObserver: reading clientWidth every frame
    // would force a style and layout pass each animation frame.
    this.cssSize = [canvas.clientWidth, canvas.clientHeight];
    this.observer = typeof ResizeObserver === "undefined" ? null : new ResizeObserver(() => {
      this.cssSize = [canvas.clientWidth, canvas.clientHeight];
      this.resize();
    });
    if (this.observer) this.observer.observe(canvas);
    this.resize();
  }

  /** Free the GL context and stop watching the canvas' size. */
  dispose() {
    if (this.observer) this.observer.disconnect();
    this.renderer.dispose();
  }

  setView(name) {
    const v = VIEWS[name];
    if (!v) return;
    this.viewName = name;
    this.camera.position.fromArray(v.pos);
    this.controls.target.fromArray(v.target);
    this.controls.update();
  }

  /** Follow the horse (the ground scrolls under it) or stay fixed (the horse passes by). */
  setFollow(on) {
    this.follow = on;
  }

  setIdColors(on) {
    this.idColors = on;
    if (this.bodies) this.bodies.setIdColors(on);
    this.ground.visible = !on;
    for (const b of this.shadows.blobs) b.material.visible = !on;
  }

  /** Render at `scale` x the canvas' CSS size (fewer pixels when the machine is busy). */
  setScale(scale) {
    this.scale = scale;
    this.resize();
  }

  resize() {
    const scale = this.scale || 1;
    const w = Math.round((this.cssSize[0] || 640) * scale);
    const h = Math.round((this.cssSize[1] || 360) * scale);
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.renderer.setSize(w, h, false);
      this.camera.aspect = w / h;
      this.camera.updateProjectionMatrix();
    }
  }

  /** Pixel (CSS px from the canvas' top left) of a world point: tests compare it with screenshots. */
  project(p) {
    const v = new Vector3(p[0], p[1], p[2]).project(this.camera);
    return [((v.x + 1) / 2) * this.canvas.clientWidth, ((1 - v.y) / 2) * this.canvas.clientHeight];
  }

  /**
   * Draw one frame. `horse`, `rider`: {pose (rig.solve), world (placed)}; `tail`,
   * `braid`: {values, groups, points} or null; `cloth`: [left flap points, right flap points]
   * or null; `travel`: the ground's shift under a
   * following camera (metres along x).
   */
  draw({ horse, rider, tail, braid, cloth, travel }) {
    if (this.bodies) this.bodies.update(horse.pose, rider.pose);
    else this.sticks.update(horse.world, rider.world);
    this.tackUsed = this.tack ? this.tack.update(horse.world, rider.world) : {};
    const hi = this.horseRig.index;
    const hw = horse.world;
    const pivotRot = hw.rotations[hi.rearPivot ?? 0];
    if (tail && tail.points) this.tail.update(tailStrands(tail.values, tail.groups, tail.points, pivotRot));
    else if (hi.tailRoot !== undefined) this.tail.update([restingTail(hw.positions[hi.tailRoot], pivotRot)]);
    this.braid.update(braid && braid.points ? [braid.points] : null);
    this.cloth.update(cloth);
    const spots = ["lfHoof", "rfHoof", "lbHoof", "rbHoof"].map((n) => {
      const p = hw.positions[hi[n]];
      return p ? [p[0] + 0.02, p[1], p[2], 0.22, 0.55] : null;
    });
    const mid = hw.positions[hi.backMid ?? 0];
    spots.push([mid[0] - 0.1, mid[1] - 1.3, mid[2], 1.3, 0.45, 0.45]);
    const seat = rider.world.positions[0];
    spots.push([seat[0], seat[1] - 1.3, seat[2], 0.5, 0.3]);
    this.shadows.update(spots);
    // A following camera keeps its place relative to the horse; the ground scrolls by the travel.
    this.groundTex.offset.x = this.follow ? (((travel / 2) % 1) + 1) % 1 : 0;
    this.groundTex.updateMatrix();
    this.renderer.render(this.scene, this.camera);
  }
}

/** Points of a chain: from `${prefix}_NN.{tx,ty,tz}` (world positions, riderlive.physics) or else `.{rx,ry,rz}` (local). */
export function chainPoints(values, names, root, rootRot, toWorld) {
  if (names.length === 0) return null;
  const pts = [root];
  if (names[0].some((n) => n.endsWith(".tx"))) {
    for (const group of names) {
      const get = (a) => values[group.find((n) => n.endsWith(a))] ?? 0;
      pts.push(toWorld([get(".tx"), get(".ty"), get(".tz")]));
    }
    return pts;
  }
  let rot = rootRot;
  let p = root;
  for (const group of names) {
    for (const [attr, axis] of [
      [".rx", [1, 0, 0]],
      [".ry", [0, 1, 0]],
      [".rz", [0, 0, 1]],
    ]) {
      const n = group.find((c) => c.endsWith(attr));
      if (n === undefined) continue;
      const h = ((values[n] ?? 0) * Math.PI) / 360;
      rot = qmul(rot, [axis[0] * Math.sin(h), axis[1] * Math.sin(h), axis[2] * Math.sin(h), Math.cos(h)]);
    }
    const step = rotate(rot, [-SEGMENT, 0, 0]);
    p = [p[0] + step[0], p[1] + step[1], p[2] + step[2]];
    pts.push(p);
  }
  return pts;
}

/** World transforms of a posed rig, placed by (rot, pos). */
export function placed(pose, rot, pos) {
  return {
    positions: pose.worldPositions.map((p) => {
      const r = rotate(rot, p);
      return [r[0] + pos[0], r[1] + pos[1], r[2] + pos[2]];
    }),
    rotations: pose.worldRotations.map((q) => qmul(rot, q)),
  };
}
