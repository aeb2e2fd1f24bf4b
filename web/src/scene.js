// The 3D view: horse and rider drawn from posed skeletons (three.js, right-handed,
// +y up; riderlive's skeleton axes are +x forward, +y up, +z right, so no conversion).

import {
  AmbientLight,
  BoxGeometry,
  BufferAttribute,
  BufferGeometry,
  Color,
  CylinderGeometry,
  DirectionalLight,
  GridHelper,
  InstancedMesh,
  Line,
  LineBasicMaterial,
  Matrix4,
  Mesh,
  MeshLambertMaterial,
  PerspectiveCamera,
  Quaternion,
  Scene,
  SphereGeometry,
  Vector3,
  WebGLRenderer,
} from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";
import { qmul, rotate } from "./rig.js";

const UP = new Vector3(0, 1, 0);
const VIEWS = {
  side: { pos: [0.15, 1.3, 4.9], target: [0.15, 1.15, 0] },
  front: { pos: [4.9, 1.5, 0.0], target: [0, 1.15, 0] },
  perspective: { pos: [3.2, 2.4, 3.6], target: [0, 1.1, 0] },
};
const CHAIN_SEGMENT = 0.07;

/** Bone segments: one instanced cylinder (a single draw call) from each joint's parent to the joint. */
class Bones {
  constructor(scene, rig, material, radius) {
    this.rig = rig;
    const geom = new CylinderGeometry(1, 1, 1, 8, 1);
    geom.translate(0, 0.5, 0);
    // The root's placement is no bone; nor is the step from the root to its first joint.
    this.drawn = rig.bones.map((b, i) => i).filter((i) => {
      const b = rig.bones[i];
      return b.parent >= 0 && rig.bones[b.parent].parent >= 0;
    });
    this.radius = this.drawn.map((i) => (typeof radius === "function" ? radius(rig.bones[i]) : radius));
    this.mesh = new InstancedMesh(geom, material, this.drawn.length);
    this.mesh.frustumCulled = false;
    scene.add(this.mesh);
    this.m = new Matrix4();
    this.q = new Quaternion();
    this.a = new Vector3();
    this.d = new Vector3();
    this.s = new Vector3();
  }

  update(world) {
    const { a, d, q, s, m } = this;
    this.drawn.forEach((i, k) => {
      const parent = this.rig.bones[i].parent;
      a.fromArray(world.positions[parent]);
      d.fromArray(world.positions[i]).sub(a);
      const len = d.length();
      if (len < 1e-6) {
        s.set(0, 0, 0);
        q.identity();
      } else {
        q.setFromUnitVectors(UP, d.multiplyScalar(1 / len));
        s.set(this.radius[k], len, this.radius[k]);
      }
      m.compose(a, q, s);
      this.mesh.setMatrixAt(k, m);
    });
    this.mesh.instanceMatrix.needsUpdate = true;
  }
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

export class View {
  constructor(canvas, horseRig, riderRig) {
    this.canvas = canvas;
    this.renderer = new WebGLRenderer({ canvas, antialias: false, powerPreference: "low-power" });
    this.renderer.setPixelRatio(1);
    this.scene = new Scene();
    this.scene.background = new Color(0x1b1f24);
    this.camera = new PerspectiveCamera(40, 1, 0.05, 100);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.enableDamping = false;
    this.scene.add(new AmbientLight(0xffffff, 1.1));
    const sun = new DirectionalLight(0xffffff, 1.6);
    sun.position.set(3, 6, -4);
    this.scene.add(sun);
    this.grid = new GridHelper(20, 20, 0x3a4450, 0x2a3038);
    this.scene.add(this.grid);

    const horseMat = new MeshLambertMaterial({ color: 0x8b5a2b });
    const hoofMat = new MeshLambertMaterial({ color: 0x222222 });
    const riderMat = new MeshLambertMaterial({ color: 0x4d7fbf });
    const skinMat = new MeshLambertMaterial({ color: 0xe0b090 });
    this.horseRig = horseRig;
    this.riderRig = riderRig;
    this.horseBones = new Bones(this.scene, horseRig, horseMat, (b) => (b.name.endsWith("Hoof") ? 0.045 : 0.04));
    this.riderBones = new Bones(this.scene, riderRig, riderMat, (b) =>
      ["lower_back", "waist", "spine_c", "spine_d", "spine_f"].includes(b.name) ? 0.09 : 0.035,
    );
    const body = new Mesh(new SphereGeometry(1, 20, 12), horseMat);
    body.scale.set(0.92, 0.3, 0.26);
    this.scene.add(body);
    this.body = body;
    const head = new Mesh(new CylinderGeometry(0.1, 0.06, 0.52, 10), horseMat);
    this.scene.add(head);
    this.horseHead = head;
    this.hooves = ["lf", "rf", "lb", "rb"].map((h) => {
      const m = new Mesh(new BoxGeometry(0.12, 0.06, 0.11), hoofMat);
      this.scene.add(m);
      return [horseRig.index[`${h}Hoof`], m];
    });
    const riderHead = new Mesh(new SphereGeometry(0.1, 16, 10), skinMat);
    this.scene.add(riderHead);
    this.riderHead = riderHead;
    this.extremities = ["lf_hand", "rt_hand", "lf_toes", "rt_toes"].map((n) => {
      const m = new Mesh(new BoxGeometry(0.09, 0.04, 0.06), n.endsWith("hand") ? skinMat : hoofMat);
      this.scene.add(m);
      return [riderRig.index[n], m];
    });
    this.chains = new Map(); // "tail" | "braid" -> Line
    this.setView("side");
    this.resize();
  }

  setView(name) {
    const v = VIEWS[name];
    this.camera.position.fromArray(v.pos);
    this.controls.target.fromArray(v.target);
    this.controls.update();
    this.viewName = name;
  }

  /** Render at `scale` x the canvas' CSS size (fewer pixels when the machine is busy). */
  setScale(scale) {
    this.scale = scale;
    this.resize();
  }

  resize() {
    const scale = this.scale || 1;
    const w = Math.round((this.canvas.clientWidth || 640) * scale);
    const h = Math.round((this.canvas.clientHeight || 360) * scale);
    if (this.canvas.width !== w || this.canvas.height !== h) {
      this.renderer.setSize(w, h, false);
      this.camera.aspect = w / h;
      this.camera.updateProjectionMatrix();
    }
  }

  /** Draw a chain (tail or braid) through world points; hidden when null. */
  chain(name, points) {
    let line = this.chains.get(name);
    if (!points) {
      if (line) line.visible = false;
      return;
    }
    if (!line || line.userData.n !== points.length) {
      if (line) this.scene.remove(line);
      const geom = new BufferGeometry();
      geom.setAttribute("position", new BufferAttribute(new Float32Array(points.length * 3), 3));
      line = new Line(geom, new LineBasicMaterial({ color: name === "tail" ? 0x3b2412 : 0xd9b36c }));
      line.userData.n = points.length;
      this.scene.add(line);
      this.chains.set(name, line);
    }
    line.visible = true;
    const attr = line.geometry.getAttribute("position");
    points.forEach((p, i) => attr.setXYZ(i, p[0], p[1], p[2]));
    attr.needsUpdate = true;
    line.geometry.computeBoundingSphere();
  }

  /** Place both skeletons; `horse` and `rider` are {positions, rotations} in world space. */
  update(horse, rider, groundShift) {
    this.horseBones.update(horse);
    this.riderBones.update(rider);
    const hi = this.horseRig.index;
    const q = new Quaternion();
    const back = horse.positions[hi.backMid];
    q.fromArray(horse.rotations[hi.backMid]);
    this.body.quaternion.copy(q);
    this.body.position.set(-0.15, -0.14, 0).applyQuaternion(q).add(new Vector3(back[0], back[1], back[2]));
    const hp = horse.positions[hi.head];
    const mp = horse.positions[hi.muzzle];
    this.horseHead.position.set((hp[0] + mp[0]) / 2, (hp[1] + mp[1]) / 2, (hp[2] + mp[2]) / 2);
    this.horseHead.quaternion.setFromUnitVectors(UP, new Vector3(hp[0] - mp[0], hp[1] - mp[1], hp[2] - mp[2]).normalize());
    for (const [i, m] of this.hooves) {
      m.position.fromArray(horse.positions[i]);
      m.position.y += 0.03;
      m.quaternion.fromArray(horse.rotations[i]);
    }
    const ri = this.riderRig.index;
    const h = rider.positions[ri.head];
    q.fromArray(rider.rotations[ri.head]);
    this.riderHead.position.set(0, 0.1, 0).applyQuaternion(q).add(new Vector3(h[0], h[1], h[2]));
    for (const [i, m] of this.extremities) {
      const p = rider.positions[i];
      q.fromArray(rider.rotations[i]);
      m.quaternion.copy(q);
      m.position.set(0.04, 0, 0).applyQuaternion(q).add(new Vector3(p[0], p[1], p[2]));
    }
    this.grid.position.x = -(((groundShift % 1) + 1) % 1);
    this.resize();
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
    const step = rotate(rot, [-CHAIN_SEGMENT, 0, 0]);
    p = [p[0] + step[0], p[1] + step[1], p[2] + step[2]];
    pts.push(p);
  }
  return pts;
}
