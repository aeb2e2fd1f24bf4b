// The tail and the braid as tapered tubes through their chains' joints (CPU-updated,
// one draw call each). With the physics on, the service publishes the skinned tail's
// bones (`tail_NN.tx/ty/tz` world positions, `qx..qw` local rotations, `fan` on the
// lower half; docs/tail.md): the centre chain is drawn thick and three strands sit
// around it at the published fan distance, as the physics' sub-chains do. The
// 400-strand reference tail is not streamed by the service, so it is not drawn here.
// Without tail channels a resting tail hangs from the horse's tail root.

import { BufferAttribute, BufferGeometry, Mesh, MeshLambertMaterial } from "three";
import { qmul, rotate } from "./rig.js";

const SIDES = 6;
/** Where a resting tail's joints are, from the tail root in the hindquarters' frame (m). */
const RESTING = [
  [0, 0, 0],
  [-0.1, -0.08, 0],
  [-0.16, -0.22, 0],
  [-0.19, -0.38, 0],
  [-0.2, -0.55, 0],
  [-0.2, -0.72, 0],
  [-0.19, -0.88, 0],
];

/** A bundle of tubes of `points` joints each, redrawn from new joint positions every frame. */
export class Tubes {
  constructor(scene, count, points, color, radius) {
    this.count = count;
    this.points = points;
    this.radius = radius; // radius(tube, t in 0..1)
    const verts = count * points * SIDES;
    this.pos = new Float32Array(verts * 3);
    this.nrm = new Float32Array(verts * 3);
    const index = [];
    for (let s = 0; s < count; s++)
      for (let k = 0; k + 1 < points; k++)
        for (let j = 0; j < SIDES; j++) {
          const a = (s * points + k) * SIDES + j;
          const b = (s * points + k) * SIDES + ((j + 1) % SIDES);
          index.push(a, b, a + SIDES, b, b + SIDES, a + SIDES);
        }
    const g = new BufferGeometry();
    g.setAttribute("position", new BufferAttribute(this.pos, 3));
    g.setAttribute("normal", new BufferAttribute(this.nrm, 3));
    g.setIndex(index);
    this.mesh = new Mesh(g, new MeshLambertMaterial({ color }));
    this.mesh.frustumCulled = false;
    scene.add(this.mesh);
  }

  /** `tubes[s]` = joint positions (at least 2; resampled to this bundle's joint count). */
  update(tubes) {
    if (!tubes) {
      this.mesh.visible = false;
      return;
    }
    this.mesh.visible = true;
    const { pos, nrm, points } = this;
    for (let s = 0; s < this.count; s++) {
      const src = tubes[Math.min(s, tubes.length - 1)];
      for (let k = 0; k < points; k++) {
        const f = (k / (points - 1)) * (src.length - 1);
        const i0 = Math.min(Math.floor(f), src.length - 2);
        const t = f - i0;
        const c = [0, 1, 2].map((a) => src[i0][a] + (src[i0 + 1][a] - src[i0][a]) * t);
        const d = [0, 1, 2].map((a) => src[i0 + 1][a] - src[i0][a]);
        const dl = Math.hypot(d[0], d[1], d[2]) || 1;
        const dir = d.map((x) => x / dl);
        // Any two directions across the tube.
        const ref = Math.abs(dir[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0];
        let u = [dir[1] * ref[2] - dir[2] * ref[1], dir[2] * ref[0] - dir[0] * ref[2], dir[0] * ref[1] - dir[1] * ref[0]];
        const ul = Math.hypot(u[0], u[1], u[2]) || 1;
        u = u.map((x) => x / ul);
        const v = [dir[1] * u[2] - dir[2] * u[1], dir[2] * u[0] - dir[0] * u[2], dir[0] * u[1] - dir[1] * u[0]];
        const r = this.radius(s, k / (points - 1));
        for (let j = 0; j < SIDES; j++) {
          const a = (2 * Math.PI * j) / SIDES;
          const n = [0, 1, 2].map((x) => u[x] * Math.cos(a) + v[x] * Math.sin(a));
          const o = ((s * points + k) * SIDES + j) * 3;
          for (let x = 0; x < 3; x++) {
            nrm[o + x] = n[x];
            pos[o + x] = c[x] + n[x] * r;
          }
        }
      }
    }
    this.mesh.geometry.getAttribute("position").needsUpdate = true;
    this.mesh.geometry.getAttribute("normal").needsUpdate = true;
  }
}

/** Joint positions of a resting tail hanging from `root`, turned with the hindquarters. */
export function restingTail(root, rot) {
  return RESTING.map((p) => {
    const r = rotate(rot, p);
    return [root[0] + r[0], root[1] + r[1], root[2] + r[2]];
  });
}

/**
 * The published tail as strands: the centre chain and three around it at the fan
 * distance, in the frame of each centre bone (`tail_00` relative to the hindquarters).
 */
export function tailStrands(values, groups, centre, hindquarters) {
  let rot = hindquarters;
  const out = [centre, [], [], []];
  groups.forEach((group, k) => {
    const get = (a) => values[group.find((n) => n.endsWith(a))];
    const q = [get(".qx"), get(".qy"), get(".qz"), get(".qw")];
    if (q.every((x) => typeof x === "number" && Number.isFinite(x))) rot = qmul(rot, q);
    const fan = Number(get(".fan")) || 0;
    const p = centre[Math.min(k + 1, centre.length - 1)];
    for (let j = 0; j < 3; j++) {
      const a = (2 * Math.PI * j) / 3;
      const o = rotate(rot, [0, fan * Math.cos(a), fan * Math.sin(a)]);
      out[j + 1].push([p[0] + o[0], p[1] + o[1], p[2] + o[2]]);
    }
  });
  for (let j = 1; j < 4; j++) out[j].unshift(centre[0]);
  return out;
}
