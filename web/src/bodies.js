// The skinned horse and rider (meshes.js) driven by the posed skeletons: every bone's
// local offset and rotation go straight into a three.js Bone; the rider's root bone is a
// child of the horse's saddle bone, as the skeletons attach them (hello `attach`).

import { Bone, MeshBasicMaterial, MeshLambertMaterial, Skeleton, SkinnedMesh } from "three";
import { horseGeometry, riderGeometry } from "./meshes.js";
import { vertexLitMaterial } from "./vertexlit.js";

function bonesOf(rig) {
  const bones = rig.bones.map((b) => {
    const bone = new Bone();
    bone.name = b.name;
    bone.position.fromArray(b.offset);
    return bone;
  });
  rig.bones.forEach((b, i) => b.parent >= 0 && bones[b.parent].add(bones[i]));
  return bones;
}

function skinned(geometry, bones, root, lights) {
  // Lit per vertex (vertexlit.js): on software WebGL, per-pixel Lambert cost the bodies' pixels
  // several times what an interpolated colour does (docs/performance.md).
  const lit = lights ? vertexLitMaterial(lights.sky, lights.sun, { vertexColors: true }) : new MeshLambertMaterial({ vertexColors: true });
  const flat = new MeshBasicMaterial({ vertexColors: true });
  const mesh = new SkinnedMesh(geometry, lit);
  mesh.frustumCulled = false; // the bounding sphere is the rest pose's
  mesh.userData = { lit, flat, colors: geometry.getAttribute("color"), ids: geometry.getAttribute("idColor") };
  root.updateMatrixWorld(true);
  mesh.updateMatrixWorld(true);
  mesh.bind(new Skeleton(bones));
  return mesh;
}

export class Bodies {
  constructor(scene, horseRig, riderRig, lights = null, saddleBone = "saddle") {
    this.horseBones = bonesOf(horseRig);
    this.riderBones = bonesOf(riderRig);
    const horseRoot = this.horseBones[0];
    scene.add(horseRoot);
    const saddle = this.horseBones[horseRig.index[saddleBone] ?? 0];
    const riderRoot = this.riderBones[0];
    saddle.add(riderRoot);
    this.horse = skinned(horseGeometry(horseRig), this.horseBones, horseRoot, lights);
    scene.add(this.horse);
    // The rider's geometry is in its own frame (the seat at the origin): bound where the
    // saddle's rest puts it.
    this.rider = skinned(riderGeometry(riderRig), this.riderBones, horseRoot, lights);
    saddle.getWorldPosition(this.rider.position);
    this.rider.updateMatrixWorld(true);
    this.rider.bind(this.rider.skeleton, this.rider.matrixWorld);
    scene.add(this.rider);
  }

  /** Flat part colours (tests find the pelvis and the saddle by colour) or the lit ones. */
  setIdColors(on) {
    for (const m of [this.horse, this.rider]) {
      const u = m.userData;
      m.geometry.setAttribute("color", on ? u.ids : u.colors);
      m.material = on ? u.flat : u.lit;
    }
  }

  set visible(on) {
    this.horse.visible = this.rider.visible = on;
  }

  /** `horse` and `rider`: poses from rig.solve (local offsets and rotations per bone). */
  update(horse, rider) {
    for (const [bones, pose] of [
      [this.horseBones, horse],
      [this.riderBones, rider],
    ])
      for (let i = 0; i < bones.length; i++) {
        bones[i].position.fromArray(pose.localOffsets[i]);
        bones[i].quaternion.fromArray(pose.localRotations[i]);
      }
  }
}
