// The parts of three.js the physmotion viewer uses, bundled into one classic script (global THREE) so
// that the page can inline it: no module loading, no network.
export {
  WebGLRenderer, Scene, PerspectiveCamera, Color, HemisphereLight, DirectionalLight,
  Mesh, Group, LineSegments, SphereGeometry, CylinderGeometry, PlaneGeometry, MeshLambertMaterial, MeshBasicMaterial,
  Vector3, Box3, LineBasicMaterial, BufferGeometry, Float32BufferAttribute,
  REVISION,
} from 'three';
export { OrbitControls } from 'three/addons/controls/OrbitControls.js';
