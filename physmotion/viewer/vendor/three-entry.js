// The parts of three.js the physmotion viewer uses, bundled into one classic script (global THREE) so
// that the page can inline it: no module loading, no network.
export {
  WebGLRenderer, Scene, PerspectiveCamera, Color, HemisphereLight, DirectionalLight,
  Mesh, Group, LineSegments, SphereGeometry, CylinderGeometry, PlaneGeometry, MeshLambertMaterial, MeshBasicMaterial,
  Vector3, Box3, LineBasicMaterial, BufferGeometry, Float32BufferAttribute,
  AnimationMixer,
  REVISION,
} from 'three';
export { OrbitControls } from 'three/addons/controls/OrbitControls.js';
// The skinned body: each motion's .glb (physmotion/io/gltf.py), inlined as base64 and parsed in the page.
export { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
