// Poses a skeleton from channel values: the JavaScript twin of riderlive/skeleton/rig.py.
// The rig comes as data (hello_skeletons()["rider"|"horse"]); quaternions are [x, y, z, w],
// vectors [x, y, z]; metres, degrees; +x forward, +y up, +z right (right-handed).

const AXIS = { x: [1, 0, 0], y: [0, 1, 0], z: [0, 0, 1] };
const ID = [0, 0, 0, 1];

const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => Math.sqrt(dot(a, a));
const unit = (a) => {
  const n = norm(a);
  return n > 0 ? [a[0] / n, a[1] / n, a[2] / n] : [0, 0, 0];
};

export function qmul(a, b) {
  const [ax, ay, az, aw] = a;
  const [bx, by, bz, bw] = b;
  return [
    aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw,
    aw * bw - ax * bx - ay * by - az * bz,
  ];
}
const conj = (q) => [-q[0], -q[1], -q[2], q[3]];
function qnorm(q) {
  const n = Math.hypot(q[0], q[1], q[2], q[3]);
  return [q[0] / n, q[1] / n, q[2] / n, q[3] / n];
}
function axisAngle(axis, deg) {
  const h = (deg * Math.PI) / 360;
  const s = Math.sin(h);
  return [axis[0] * s, axis[1] * s, axis[2] * s, Math.cos(h)];
}
export function rotate(q, v) {
  const [qx, qy, qz, qw] = q;
  const tx = 2 * (qy * v[2] - qz * v[1]);
  const ty = 2 * (qz * v[0] - qx * v[2]);
  const tz = 2 * (qx * v[1] - qy * v[0]);
  return [v[0] + qw * tx + qy * tz - qz * ty, v[1] + qw * ty + qz * tx - qx * tz, v[2] + qw * tz + qx * ty - qy * tx];
}
function fromBasis(x, y, z) {
  const [m00, m10, m20] = x;
  const [m01, m11, m21] = y;
  const [m02, m12, m22] = z;
  const tr = m00 + m11 + m22;
  let q;
  if (tr > 0) {
    const s = 2 * Math.sqrt(tr + 1);
    q = [(m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s];
  } else if (m00 > m11 && m00 > m22) {
    const s = 2 * Math.sqrt(1 + m00 - m11 - m22);
    q = [0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s];
  } else if (m11 > m22) {
    const s = 2 * Math.sqrt(1 + m11 - m00 - m22);
    q = [(m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s];
  } else {
    const s = 2 * Math.sqrt(1 + m22 - m00 - m11);
    q = [(m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s];
  }
  q = qnorm(q);
  return q[3] >= 0 ? q : [-q[0], -q[1], -q[2], -q[3]];
}
function frameRotation(d0, n0, d1, n1) {
  const b0 = cross(d0, n0);
  const b1 = cross(d1, n1);
  const col = [0, 1, 2].map((k) => add(add(scale(d1, d0[k]), scale(n1, n0[k])), scale(b1, b0[k])));
  return fromBasis(col[0], col[1], col[2]);
}
function anyPerpendicular(u) {
  return unit(cross(u, Math.abs(u[0]) < 0.9 ? AXIS.x : AXIS.y));
}

/** Prepare a rig (from the hello) for fast posing. */
export function compileRig(data) {
  const bones = data.bones;
  const index = Object.fromEntries(bones.map((b, i) => [b.name, i]));
  const rest = [];
  bones.forEach((b, i) => (rest[i] = b.parent < 0 ? b.offset.slice() : add(rest[b.parent], b.offset)));
  const drive = (d) => ({ channel: d.channel, bone: index[d.bone], axis: AXIS[d.axis], sign: d.sign });
  const offset = (o) => ({ channel: o.channel, axis: AXIS[o.axis], sign: o.sign });
  return {
    bones,
    index,
    rest,
    neutral: data.neutral,
    rotations: data.rotations.map(drive),
    translations: data.translations.map(drive),
    chains: data.chains.map((c) => ({
      upper: index[c.upper],
      lower: index[c.lower],
      end: index[c.end],
      frame: c.frame === null ? -1 : index[c.frame],
      targetRest: c.target_rest,
      poleRest: c.pole_rest,
      target: c.target.map(offset),
      pole: c.pole.map(offset),
    })),
  };
}

function forward(rig, lrot, loff) {
  const wrot = [];
  const wpos = [];
  rig.bones.forEach((b, i) => {
    if (b.parent < 0) {
      wrot[i] = lrot[i];
      wpos[i] = loff[i];
    } else {
      const pr = wrot[b.parent];
      wrot[i] = qmul(pr, lrot[i]);
      wpos[i] = add(wpos[b.parent], rotate(pr, loff[i]));
    }
  });
  return [wrot, wpos];
}

/** Pose a compiled rig; `values` maps channel name -> value (missing = neutral). */
export function solve(rig, values) {
  const delta = (ch) => {
    const v = values[ch];
    return typeof v === "number" && Number.isFinite(v) ? v - (rig.neutral[ch] ?? 0) : 0;
  };
  const n = rig.bones.length;
  const lrot = new Array(n).fill(ID);
  const loff = rig.bones.map((b) => b.offset);
  for (const d of rig.rotations) lrot[d.bone] = qmul(axisAngle(d.axis, d.sign * delta(d.channel)), lrot[d.bone]);
  for (const d of rig.translations) loff[d.bone] = add(loff[d.bone], scale(d.axis, d.sign * delta(d.channel)));
  const endTurn = rig.chains.map((c) => lrot[c.end]);
  let [wrot, wpos] = forward(rig, lrot, loff);

  rig.chains.forEach((c, k) => {
    const frot = c.frame < 0 ? ID : wrot[c.frame];
    const fpos = c.frame < 0 ? [0, 0, 0] : wpos[c.frame];
    let tl = c.targetRest;
    for (const o of c.target) tl = add(tl, scale(o.axis, o.sign * delta(o.channel)));
    let pl = c.poleRest;
    for (const o of c.pole) pl = add(pl, scale(o.axis, o.sign * delta(o.channel)));
    const target = add(fpos, rotate(frot, tl));
    const pole = add(fpos, rotate(frot, pl));
    const a = wpos[c.upper];
    const l1 = norm(loff[c.lower]);
    const l2 = norm(loff[c.end]);
    const toT = sub(target, a);
    const dist = norm(toT);
    const u = dist > 1e-12 ? unit(toT) : anyPerpendicular(unit(pole));
    const cl = Math.min(Math.max(dist, Math.abs(l1 - l2) + 1e-9), l1 + l2 - 1e-9);
    const cosA = (l1 * l1 + cl * cl - l2 * l2) / (2 * l1 * cl);
    const sinA = Math.sqrt(Math.max(0, 1 - cosA * cosA));
    const toP = sub(pole, a);
    let v = sub(toP, scale(u, dot(toP, u)));
    v = norm(v) > 1e-12 ? unit(v) : anyPerpendicular(u);
    const elbow = add(a, add(scale(u, l1 * cosA), scale(v, l1 * sinA)));
    const end = add(a, scale(u, cl));
    const d0u = unit(loff[c.lower]);
    const d0l = unit(loff[c.end]);
    const n0 = unit(cross(d0u, d0l));
    const d1u = unit(sub(elbow, a));
    const d1l = unit(sub(end, elbow));
    const n1 = unit(cross(d1u, d1l));
    const upperW = frameRotation(d0u, n0, d1u, n1);
    const lowerW = frameRotation(d0l, n0, d1l, n1);
    const pu = rig.bones[c.upper].parent;
    lrot[c.upper] = qmul(conj(pu >= 0 ? wrot[pu] : ID), upperW);
    lrot[c.lower] = qmul(conj(upperW), lowerW);
    lrot[c.end] = qmul(conj(lowerW), qmul(frot, endTurn[k]));
    [wrot, wpos] = forward(rig, lrot, loff);
  });
  return { localRotations: lrot.map(qnorm), localOffsets: loff, worldRotations: wrot, worldPositions: wpos };
}
