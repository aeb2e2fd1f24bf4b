// Reins and stirrups, drawn between the two skeletons each frame (one instanced draw of
// thin cylinders). They use the horse skeleton's tack bones when it has them (the bit
// rings `leftRein` / `rightRein`, the irons `leftStirrup` / `rightStirrup` hung from
// `leftStirrupBar` / `rightStirrupBar`; docs/skeleton.md); without them, the reins run
// from the corners of the mouth (between the head and muzzle joints) to the rider's
// hands, and each stirrup hangs from the saddle to the ball of the foot.

import { CylinderGeometry, InstancedMesh, Matrix4, MeshLambertMaterial, Quaternion, Vector3 } from "three";
import { rotate } from "./rig.js";

const UP = new Vector3(0, 1, 0);
const SEGMENTS = 8; // two reins of 2 pieces, two leathers, two irons
const HIDDEN = new Matrix4().makeScale(0, 0, 0);

/** The first of `names` that `rig` has, or -1. */
export function findBone(rig, names) {
  for (const n of names) if (n in rig.index) return rig.index[n];
  return -1;
}

const mix = (a, b, t) => [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t];
const plus = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];

export class Tack {
  constructor(scene, horseRig, riderRig) {
    const geom = new CylinderGeometry(1, 1, 1, 6, 1);
    geom.translate(0, 0.5, 0);
    this.mesh = new InstancedMesh(geom, new MeshLambertMaterial({ color: 0x3a2210 }), SEGMENTS);
    this.mesh.frustumCulled = false;
    scene.add(this.mesh);
    const side = (s) => {
      const long = s === "lf" ? "left" : "right";
      return {
        ring: findBone(horseRig, [`${long}Rein`]),
        hand: findBone(riderRig, [`${s}_hand`]),
        stirrup: findBone(horseRig, [`${long}Stirrup`]),
        bar: findBone(horseRig, [`${long}StirrupBar`]),
        foot: findBone(riderRig, [`${s}_foot`]),
        toes: findBone(riderRig, [`${s}_toes`]),
      };
    };
    this.sides = { lf: side("lf"), rt: side("rt") };
    this.h = {
      head: findBone(horseRig, ["head"]),
      muzzle: findBone(horseRig, ["muzzle"]),
      saddle: findBone(horseRig, ["saddle"]),
    };
    this.uses = { reinBones: this.sides.lf.ring >= 0, stirrupBones: this.sides.lf.stirrup >= 0 };
    this.m = new Matrix4();
    this.q = new Quaternion();
    this.a = new Vector3();
    this.d = new Vector3();
    this.s = new Vector3();
    this.k = 0;
  }

  segment(p0, p1, radius) {
    const { a, d, q, s, m } = this;
    a.fromArray(p0);
    d.fromArray(p1).sub(a);
    const len = d.length();
    if (len < 1e-6 || this.k >= SEGMENTS) return;
    q.setFromUnitVectors(UP, d.multiplyScalar(1 / len));
    s.set(radius, len, radius);
    m.compose(a, q, s);
    this.mesh.setMatrixAt(this.k++, m);
  }

  /** `horse`, `rider`: world {positions, rotations}; returns the points used (for tests). */
  update(horse, rider) {
    this.k = 0;
    const hp = horse.positions;
    const used = {};
    const { head, muzzle, saddle } = this.h;
    for (const [s, z] of [
      ["lf", -1],
      ["rt", 1],
    ]) {
      const b = this.sides[s];
      // Rein: bit -> (sagging) -> the hand's grip.
      let mouth = null;
      if (b.ring >= 0) mouth = hp[b.ring];
      else if (head >= 0 && muzzle >= 0) mouth = plus(mix(hp[head], hp[muzzle], 0.8), rotate(horse.rotations[head], [0, 0, 0.06 * z]));
      const grip = b.hand >= 0 ? plus(rider.positions[b.hand], rotate(rider.rotations[b.hand], [0.05, 0, 0])) : null;
      if (mouth && grip) {
        const mid = mix(mouth, grip, 0.5);
        const sag = [mid[0], mid[1] - 0.04, mid[2]];
        this.segment(mouth, sag, 0.008);
        this.segment(sag, grip, 0.008);
        used[`${s}_rein`] = [mouth, grip];
      }
      // Stirrup: the leather from the saddle's bar to the iron, the iron under the foot.
      if (saddle < 0 || b.foot < 0) continue;
      const bar = b.bar >= 0 ? hp[b.bar] : plus(hp[saddle], rotate(horse.rotations[saddle], [0.1, -0.02, 0.17 * z]));
      let iron;
      if (b.stirrup >= 0) iron = hp[b.stirrup];
      else iron = b.toes >= 0 ? mix(rider.positions[b.foot], rider.positions[b.toes], 0.55) : rider.positions[b.foot];
      const tread = [iron[0], iron[1] - 0.035, iron[2]];
      this.segment(bar, tread, 0.012);
      const fwd = rotate(horse.rotations[saddle], [0.06, 0, 0]);
      this.segment(plus(tread, fwd), [tread[0] - fwd[0], tread[1] - fwd[1], tread[2] - fwd[2]], 0.012);
      used[`${s}_stirrup`] = [bar, iron];
    }
    for (let k = this.k; k < SEGMENTS; k++) this.mesh.setMatrixAt(k, HIDDEN);
    this.mesh.instanceMatrix.needsUpdate = true;
    return used;
  }
}
