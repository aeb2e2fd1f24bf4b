// The primitive renderer (?render=sticks): each skeleton as one instanced draw of
// cylinders, an ellipsoid body, a cylinder head, boxes for hooves, hands and feet. Kept
// as the baseline of bench/bench_page.py and for looking at the bare skeletons.

import { BoxGeometry, CylinderGeometry, InstancedMesh, Matrix4, Mesh, MeshLambertMaterial, Quaternion, SphereGeometry, Vector3 } from "three";

const UP = new Vector3(0, 1, 0);

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
    this.radius = this.drawn.map((i) => radius(rig.bones[i]));
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

export class Sticks {
  constructor(scene, horseRig, riderRig) {
    const horseMat = new MeshLambertMaterial({ color: 0x8b5a2b });
    const hoofMat = new MeshLambertMaterial({ color: 0x222222 });
    const riderMat = new MeshLambertMaterial({ color: 0x4d7fbf });
    const skinMat = new MeshLambertMaterial({ color: 0xe0b090 });
    this.horseRig = horseRig;
    this.riderRig = riderRig;
    this.horseBones = new Bones(scene, horseRig, horseMat, (b) => (b.name.endsWith("Hoof") ? 0.045 : 0.04));
    this.riderBones = new Bones(scene, riderRig, riderMat, (b) =>
      ["lower_back", "waist", "spine_c", "spine_d", "spine_f"].includes(b.name) ? 0.09 : 0.035,
    );
    const add = (m) => (scene.add(m), m);
    this.body = add(new Mesh(new SphereGeometry(1, 20, 12), horseMat));
    this.body.scale.set(0.92, 0.3, 0.26);
    this.horseHead = add(new Mesh(new CylinderGeometry(0.1, 0.06, 0.52, 10), horseMat));
    this.hooves = ["lf", "rf", "lb", "rb"].map((h) => [horseRig.index[`${h}Hoof`], add(new Mesh(new BoxGeometry(0.12, 0.06, 0.11), hoofMat))]);
    this.riderHead = add(new Mesh(new SphereGeometry(0.1, 16, 10), skinMat));
    this.extremities = ["lf_hand", "rt_hand", "lf_toes", "rt_toes"].map((n) => [
      riderRig.index[n],
      add(new Mesh(new BoxGeometry(0.09, 0.04, 0.06), n.endsWith("hand") ? skinMat : hoofMat)),
    ]);
    this.q = new Quaternion();
  }

  /** `horse` and `rider`: {positions, rotations} in world space. */
  update(horse, rider) {
    this.horseBones.update(horse);
    this.riderBones.update(rider);
    const hi = this.horseRig.index;
    const q = this.q;
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
  }
}
