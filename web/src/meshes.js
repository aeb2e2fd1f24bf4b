// Procedural skinned bodies for the horse and the rider, built once from the skeletons'
// rest positions (metres, +x forward, +y up, +z right; every bone's rest rotation is the
// identity, so a bone's rest frame is a translation). Each body is one SkinnedMesh (one
// draw call) of lofted rings: a ring follows the bone it is skinned to, rings at a joint
// blend the two bones meeting there. Vertex colours paint it; `idColor` holds flat part
// colours for tests (riderlive.setIdColors).

import { BufferAttribute, BufferGeometry, Color } from "three";

/**
 * Vertices around each ring: the count a part asks for x DETAIL, at least 6. At previs
 * distance (a 780x370 px view, the horse ~250 px long) 0.6 keeps the shapes (screenshots
 * compared by eye) and takes 40 % of the skinned vertices (1776 -> 1064) off SwiftShader's
 * vertex work (docs/performance.md).
 */
export const DETAIL = 0.6;
const around = (n) => Math.max(6, Math.round(n * DETAIL));

const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const addv = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const unit = (a) => mul(a, 1 / (Math.hypot(a[0], a[1], a[2]) || 1));
const lerp = (a, b, t) => addv(a, mul(sub(b, a), t));

/** Flat colours of the parts a test looks for in a screenshot (riderlive.setIdColors(true)). */
export const ID_COLORS = { pelvis: 0x00ff00, saddle: 0xff0000, horse: 0x0000ff, rider: 0xffff00, other: 0x808080 };

export const PALETTE = {
  coat: 0x7b4a27,
  dark: 0x1c1511,
  hoof: 0x2b2724,
  blaze: 0xe8e0d0,
  leather: 0x4a2c17,
  pad: 0xe3ded2,
  jacket: 0x2e4f80,
  breeches: 0xd9cfb4,
  boots: 0x17171a,
  skin: 0xe0b090,
  helmet: 0x202226,
};

class Builder {
  constructor() {
    this.pos = [];
    this.col = [];
    this.ids = [];
    this.si = [];
    this.sw = [];
    this.index = [];
  }

  vertex(p, color, id, skin) {
    this.pos.push(p[0], p[1], p[2]);
    this.col.push(color.r, color.g, color.b);
    this.ids.push(id.r, id.g, id.b);
    const s = skin.slice(0, 4);
    const total = s.reduce((a, [, w]) => a + w, 0) || 1;
    for (let k = 0; k < 4; k++) {
      this.si.push(s[k] ? s[k][0] : 0);
      this.sw.push(s[k] ? s[k][1] / total : 0);
    }
    return this.pos.length / 3 - 1;
  }

  /**
   * A lofted tube through ring centres `c` with half-widths `r` ([along `side`, across])
   * and per-ring skin weights [[bone, w], ...]; closed by cones of `caps` metres.
   */
  loft({ c, r, skin, color, id = "other", side = [0, 0, 1], segments: seg = 12, caps = [0.02, 0.02] }) {
    const segments = around(seg);
    const col = new Color(color);
    const idc = new Color(ID_COLORS[id]);
    const n = c.length;
    const ring = [];
    for (let k = 0; k < n; k++) {
      const d = unit(sub(c[Math.min(k + 1, n - 1)], c[Math.max(k - 1, 0)]));
      let u = sub(side, mul(d, dot(side, d)));
      if (Math.hypot(u[0], u[1], u[2]) < 1e-3) u = sub([1, 0, 0], mul(d, d[0]));
      u = unit(u);
      const v = cross(d, u);
      const [ra, rb] = Array.isArray(r[k]) ? r[k] : [r[k], r[k]];
      const ids = [];
      for (let j = 0; j < segments; j++) {
        const a = (2 * Math.PI * j) / segments;
        ids.push(this.vertex(addv(c[k], addv(mul(u, ra * Math.cos(a)), mul(v, rb * Math.sin(a)))), col, idc, skin[k]));
      }
      ring.push({ ids, d });
    }
    for (let k = 0; k + 1 < n; k++)
      for (let j = 0; j < segments; j++) {
        const a = ring[k].ids[j];
        const b = ring[k].ids[(j + 1) % segments];
        const cc = ring[k + 1].ids[j];
        const dd = ring[k + 1].ids[(j + 1) % segments];
        this.index.push(a, b, cc, b, dd, cc);
      }
    const tip0 = this.vertex(addv(c[0], mul(ring[0].d, -caps[0])), col, idc, skin[0]);
    const tip1 = this.vertex(addv(c[n - 1], mul(ring[n - 1].d, caps[1])), col, idc, skin[n - 1]);
    for (let j = 0; j < segments; j++) {
      this.index.push(ring[0].ids[(j + 1) % segments], ring[0].ids[j], tip0);
      this.index.push(ring[n - 1].ids[j], ring[n - 1].ids[(j + 1) % segments], tip1);
    }
  }

  /** An ellipsoid with semi-axes `radii` along `axis` and two perpendiculars. */
  ellipsoid({ center, radii, axis = [1, 0, 0], side = [0, 0, 1], skin, color, id = "other", rings = 6, segments = 12 }) {
    const a = unit(axis);
    const c = [];
    const r = [];
    const sk = [];
    for (let k = 1; k < rings; k++) {
      const phi = Math.PI * (1 - k / rings);
      const p = addv(center, mul(a, radii[0] * Math.cos(phi)));
      c.push(p);
      r.push([radii[2] * Math.sin(phi), radii[1] * Math.sin(phi)]);
      sk.push(typeof skin === "function" ? skin(p) : skin);
    }
    const cap = radii[0] * (1 - Math.cos(Math.PI / rings));
    this.loft({ c, r, skin: sk, color, id, side, segments, caps: [cap, cap] });
  }

  geometry() {
    const g = new BufferGeometry();
    g.setAttribute("position", new BufferAttribute(new Float32Array(this.pos), 3));
    g.setAttribute("color", new BufferAttribute(new Float32Array(this.col), 3));
    g.setAttribute("idColor", new BufferAttribute(new Float32Array(this.ids), 3));
    g.setAttribute("skinIndex", new BufferAttribute(new Uint16Array(this.si), 4));
    g.setAttribute("skinWeight", new BufferAttribute(new Float32Array(this.sw), 4));
    g.setIndex(this.index);
    g.computeVertexNormals();
    return g;
  }
}

/** Bone index by name, or -1: bodies degrade to what a skeleton has. */
const finder = (rig) => (name) => (name in rig.index ? rig.index[name] : -1);

/** Skin a point to `a` before `x0`, to `b` after `x1`, blended in between (along `axis`). */
function blend(a, b, x0, x1, axis = 0) {
  return (p) => {
    const t = Math.min(1, Math.max(0, (p[axis] - x0) / (x1 - x0)));
    return t <= 0 ? [[a, 1]] : t >= 1 ? [[b, 1]] : [[a, 1 - t], [b, t]];
  };
}

/** A limb segment from joint `i` to joint `j` skinned to bone `i`, blended into `i`'s parent at the top. */
function limb(bld, rig, i, j, r0, r1, color, { id = "other", parentBlend = 0, extend = 0, caps } = {}) {
  if (i < 0 || j < 0) return;
  const a = rig.rest[i];
  const b = rig.rest[j];
  const e = mul(unit(sub(b, a)), extend);
  const parent = rig.bones[i].parent;
  const top = parentBlend > 0 && parent >= 0 ? [[i, 1 - parentBlend], [parent, parentBlend]] : [[i, 1]];
  bld.loft({
    c: [sub(a, e), lerp(a, b, 0.5), addv(b, e)],
    r: [r0, (r0 + r1) / 2, r1],
    skin: [top, [[i, 1]], [[i, 1]]],
    color,
    id,
    caps: caps || [r0 * 0.6, r1 * 0.6],
  });
}

/** The horse: barrel, neck, head, legs, saddle and pad; the tail is drawn apart (tail.js). */
export function horseGeometry(rig) {
  const bone = finder(rig);
  const bld = new Builder();
  const P = PALETTE;
  const rest = (n) => rig.rest[bone(n)];
  const pivot = bone("rearPivot");
  const back = bone("backMid") >= 0 ? bone("backMid") : pivot;
  const saddle = rest("saddle") || [0.05, 1.46, 0];
  const withers = rest("shoulders") || [0.55, 1.14, 0];
  // Barrel along x, from the buttock to the chest; its top runs under the saddle.
  const xs = [-1.02, -0.93, -0.72, -0.45, -0.15, 0.15, 0.42, 0.66, 0.8];
  const tops = [1.3, 1.4, 1.44, 1.43, saddle[1] - 0.05, saddle[1] - 0.05, 1.46, 1.42, 1.28];
  const bottoms = [1.1, 1.0, 0.92, 0.9, 0.84, 0.84, 0.88, 0.96, 1.06];
  const widths = [0.1, 0.2, 0.27, 0.28, 0.3, 0.3, 0.27, 0.21, 0.12];
  const skinBarrel = blend(pivot, back, -0.45, 0.0);
  bld.loft({
    c: xs.map((x, k) => [x, (tops[k] + bottoms[k]) / 2, 0]),
    r: xs.map((_, k) => [widths[k], (tops[k] - bottoms[k]) / 2]),
    skin: xs.map((x) => skinBarrel([x, 0, 0])),
    color: P.coat,
    id: "horse",
    segments: 16,
    caps: [0.05, 0.06],
  });
  // Neck from inside the chest to the poll, then the head down to the muzzle.
  const neck = bone("neck");
  const head = bone("head");
  const muzzle = bone("muzzle");
  if (neck >= 0 && head >= 0) {
    const n0 = rig.rest[neck];
    const h0 = rig.rest[head];
    const shoulders = bone("shoulders") >= 0 ? bone("shoulders") : back;
    bld.loft({
      c: [[withers[0] - 0.05, withers[1] + 0.08, 0], lerp(n0, h0, 0.05), lerp(n0, h0, 0.5), lerp(n0, h0, 0.92)],
      r: [[0.17, 0.3], [0.13, 0.2], [0.1, 0.15], [0.09, 0.11]],
      skin: [[[shoulders, 1]], [[shoulders, 0.5], [neck, 0.5]], [[neck, 1]], [[neck, 0.6], [head, 0.4]]],
      color: P.coat,
      id: "horse",
      segments: 14,
      caps: [0.05, 0.04],
    });
    // Mane: a dark crest along the top of the neck.
    const up = [-0.5, 0.8, 0];
    bld.loft({
      c: [addv(lerp(n0, h0, 0.0), mul(up, 0.13)), addv(lerp(n0, h0, 0.5), mul(up, 0.12)), addv(lerp(n0, h0, 0.95), mul(up, 0.1))],
      r: [[0.025, 0.06], [0.025, 0.05], [0.02, 0.03]],
      skin: [[[shoulders, 0.5], [neck, 0.5]], [[neck, 1]], [[neck, 0.5], [head, 0.5]]],
      color: P.dark,
      id: "horse",
      segments: 6,
    });
    if (muzzle >= 0) {
      const m0 = rig.rest[muzzle];
      bld.loft({
        c: [lerp(h0, m0, -0.05), lerp(h0, m0, 0.35), lerp(h0, m0, 0.8), lerp(h0, m0, 1.0)],
        r: [[0.1, 0.12], [0.085, 0.1], [0.065, 0.075], [0.06, 0.06]],
        skin: [[[head, 1]], [[head, 1]], [[head, 1]], [[head, 1]]],
        color: P.coat,
        id: "horse",
        segments: 12,
        caps: [0.05, 0.03],
      });
      for (const z of [-0.05, 0.05]) {
        const ear = addv(h0, [-0.03, 0.04, z]);
        bld.loft({ c: [ear, addv(ear, [-0.02, 0.1, z * 0.3])], r: [0.025, 0.012], skin: [[[head, 1]], [[head, 1]]], color: P.coat, id: "horse", segments: 6 });
      }
    }
  }
  // Legs: upper, cannon, pastern and hoof per leg.
  for (const h of ["lf", "rf", "lb", "rb"]) {
    const front = h[1] === "f";
    const leg = bone(`${h}Leg`);
    const mid = bone(`${h}${front ? "Knee" : "Hock"}`);
    const fet = bone(`${h}Fetlock`);
    const hoof = bone(`${h}Hoof`);
    limb(bld, rig, leg, mid, front ? 0.13 : 0.17, 0.065, P.coat, { id: "horse", parentBlend: 0.3 });
    limb(bld, rig, mid, fet, 0.055, 0.045, P.coat, { id: "horse", extend: 0.02 });
    limb(bld, rig, fet, hoof, 0.045, 0.05, P.dark, { id: "horse", extend: 0.02 });
    if (hoof >= 0) {
      const p = rig.rest[hoof];
      bld.loft({
        c: [addv(p, [0.01, 0.06, 0]), addv(p, [0.02, 0.0, 0])],
        r: [0.05, 0.065],
        skin: [[[hoof, 1]], [[hoof, 1]]],
        color: P.hoof,
        id: "horse",
        segments: 10,
        caps: [0.01, 0.005],
      });
    }
  }
  // Saddle pad and saddle on the saddle bone; its seat is the rider's root.
  const sb = bone("saddle");
  if (sb >= 0) {
    const s = rig.rest[sb];
    const sk = [[sb, 1]];
    bld.loft({
      c: [addv(s, [-0.3, -0.05, 0]), addv(s, [0, -0.06, 0]), addv(s, [0.3, -0.04, 0])],
      r: [[0.3, 0.02], [0.32, 0.025], [0.3, 0.02]],
      skin: [sk, sk, sk],
      color: P.pad,
      id: "horse",
      segments: 12,
    });
    bld.loft({
      c: [addv(s, [-0.22, 0.03, 0]), addv(s, [-0.12, -0.01, 0]), addv(s, [0.06, -0.02, 0]), addv(s, [0.2, 0.02, 0])],
      r: [[0.17, 0.04], [0.2, 0.035], [0.2, 0.03], [0.13, 0.05]],
      skin: [sk, sk, sk, sk],
      color: P.leather,
      id: "saddle",
      segments: 12,
    });
  }
  return bld.geometry();
}

/** The rider: pelvis in the seat, torso over the spine bones, head and helmet, arms, legs, boots. */
export function riderGeometry(rig) {
  const bone = finder(rig);
  const bld = new Builder();
  const P = PALETTE;
  const hips = bone("hips");
  const at = (n) => rig.rest[bone(n)];
  // Pelvis: its underside is the seat (the skeleton's origin, on the saddle bone).
  if (hips >= 0) {
    bld.ellipsoid({ center: [-0.01, 0.075, 0], radii: [0.13, 0.085, 0.17], skin: [[hips, 1]], color: P.breeches, id: "pelvis" });
  }
  // Torso rings on the spine joints (each ring follows its bone).
  const spine = [
    ["hips", [0.16, 0.11], 0.02],
    ["lower_back", [0.15, 0.1], 0.0],
    ["waist", [0.145, 0.095], 0.0],
    ["spine_c", [0.155, 0.1], 0.0],
    ["spine_d", [0.17, 0.11], 0.0],
    ["spine_f", [0.19, 0.11], 0.0],
  ].filter(([n]) => bone(n) >= 0);
  if (spine.length >= 2) {
    const c = spine.map(([n, , dy]) => addv(at(n), [0, dy, 0]));
    const last = c[c.length - 1];
    c.push(addv(last, [0, 0.08, 0]));
    const r = [...spine.map(([, rr]) => rr), [0.15, 0.08]];
    const skin = [...spine.map(([n]) => [[bone(n), 1]]), [[bone(spine[spine.length - 1][0]), 1]]];
    bld.loft({ c, r, skin, color: P.jacket, id: "rider", side: [0, 0, 1], segments: 14, caps: [0.02, 0.03] });
  }
  const neck = bone("neck");
  const head = bone("head");
  if (neck >= 0 && head >= 0) {
    bld.loft({ c: [addv(at("neck"), [0, -0.04, 0]), at("head")], r: [0.055, 0.05], skin: [[[neck, 1]], [[neck, 0.5], [head, 0.5]]], color: P.skin, id: "rider", segments: 10 });
    const hc = addv(at("head"), [0.01, 0.11, 0]);
    bld.ellipsoid({ center: hc, radii: [0.115, 0.1, 0.085], axis: [0, 1, 0], side: [0, 0, 1], skin: [[head, 1]], color: P.skin, id: "rider" });
    bld.ellipsoid({ center: addv(hc, [-0.01, 0.035, 0]), radii: [0.1, 0.11, 0.095], axis: [0, 1, 0], side: [0, 0, 1], skin: [[head, 1]], color: P.helmet, id: "rider", rings: 4 });
    bld.loft({ c: [addv(hc, [0.08, 0.06, 0]), addv(hc, [0.14, 0.05, 0])], r: [[0.08, 0.012], [0.07, 0.008]], skin: [[[head, 1]], [[head, 1]]], color: P.helmet, id: "rider", segments: 8 });
  }
  for (const s of ["lf", "rt"]) {
    const b = (n) => bone(`${s}_${n}`);
    limb(bld, rig, b("shoulder"), b("upperarm"), 0.05, 0.055, P.jacket, { id: "rider" });
    limb(bld, rig, b("upperarm"), b("forearm"), 0.052, 0.042, P.jacket, { id: "rider", extend: 0.02 });
    limb(bld, rig, b("forearm"), b("hand"), 0.04, 0.032, P.jacket, { id: "rider", extend: 0.01 });
    if (b("hand") >= 0) {
      const h = at(`${s}_hand`);
      const f = unit(sub(h, at(`${s}_forearm`)));
      bld.loft({ c: [h, addv(h, mul(f, 0.09))], r: [[0.035, 0.02], [0.03, 0.018]], skin: [[[b("hand"), 1]], [[b("hand"), 1]]], color: P.skin, id: "rider", segments: 8 });
    }
    limb(bld, rig, b("thigh"), b("shin"), 0.085, 0.06, P.breeches, { id: "rider", parentBlend: 0.25, extend: 0.02 });
    if (b("shin") >= 0 && b("foot") >= 0) {
      const k = at(`${s}_shin`);
      const a = at(`${s}_foot`);
      const sk = [[b("shin"), 1]];
      bld.loft({ c: [lerp(k, a, -0.03), lerp(k, a, 0.3), lerp(k, a, 1.02)], r: [0.058, 0.056, 0.045], skin: [sk, sk, sk], color: P.boots, id: "rider", segments: 10 });
    }
    if (b("foot") >= 0 && b("toes") >= 0) {
      const a = at(`${s}_foot`);
      const t = at(`${s}_toes`);
      const sk = [[b("foot"), 1]];
      bld.loft({ c: [addv(a, [-0.06, -0.02, 0]), lerp(a, t, 0.5), addv(t, [0.03, 0, 0])], r: [[0.04, 0.045], [0.045, 0.04], [0.04, 0.03]], skin: [sk, sk, [[b("toes"), 1]]], color: P.boots, id: "rider", segments: 10, side: [0, 0, 1] });
    }
  }
  return bld.geometry();
}
