// A Lambert material lit per vertex (Gouraud) rather than per pixel: the same light as
// three.js' MeshLambertMaterial under one hemisphere and one directional light, no shadows
// ((hemisphere + sun * cos) / pi x albedo, as `flatLight` in scene.js bakes for the ground),
// computed at the vertices and sRGB-encoded there, so a pixel costs one interpolated colour.
// On a software rasteriser (SwiftShader) the bodies' pixels then cost what unlit ones do;
// the bodies are smooth, lofted tubes, so the per-vertex light looks the same at previs
// distance. Works for skinned meshes (three.js' skinning chunks) and vertex colours.

import { Color, ShaderMaterial, Vector3 } from "three";

const VERTEX = `
#include <common>
#include <skinning_pars_vertex>
#include <colorspace_pars_fragment>
uniform vec3 albedo;
uniform vec3 skyColor;
uniform vec3 groundColor;
uniform vec3 skyDir;
uniform vec3 sunColor;
uniform vec3 sunDir;
varying vec3 vLit;
void main() {
  #include <beginnormal_vertex>
  #include <skinbase_vertex>
  #include <skinnormal_vertex>
  #include <begin_vertex>
  #include <skinning_vertex>
  #include <project_vertex>
  vec3 n = normalize(mat3(modelMatrix) * objectNormal);
  vec3 light = mix(groundColor, skyColor, 0.5 * dot(n, skyDir) + 0.5) + sunColor * max(dot(n, sunDir), 0.0);
  vec3 base = albedo;
  #ifdef USE_COLOR
  base *= color;
  #endif
  vLit = sRGBTransferOETF(vec4(base * light * RECIPROCAL_PI, 1.0)).rgb;
}`;

const FRAGMENT = `
varying vec3 vLit;
void main() { gl_FragColor = vec4(vLit, 1.0); }`;

/** Light per unit albedo from `sky` (HemisphereLight) and `sun` (DirectionalLight), world frame. */
export function vertexLitMaterial(sky, sun, { color = 0xffffff, vertexColors = false } = {}) {
  const dir = (v) => v.clone().normalize();
  return new ShaderMaterial({
    vertexColors,
    uniforms: {
      albedo: { value: new Color(color) },
      skyColor: { value: sky.color.clone().multiplyScalar(sky.intensity) },
      groundColor: { value: sky.groundColor.clone().multiplyScalar(sky.intensity) },
      skyDir: { value: dir(new Vector3().copy(sky.position)) },
      sunColor: { value: sun.color.clone().multiplyScalar(sun.intensity) },
      sunDir: { value: dir(sun.position.clone().sub(sun.target.position)) },
    },
    vertexShader: VERTEX,
    fragmentShader: FRAGMENT,
  });
}
