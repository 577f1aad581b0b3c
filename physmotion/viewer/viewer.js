// physmotion motion viewer: plays the motions inlined in #motion-data with three.js (global THREE).
// Data layout: see physmotion/viewer/__init__.py (scene_data). Metres, Y up, floor at y = 0.
(function () {
  "use strict";
  const CONTACT = 0xe600c8; // the colour physmotion render uses for foot contacts
  const status = document.getElementById("status");

  function fail(message) {
    status.dataset.state = "error";
    status.textContent = message;
  }
  window.addEventListener("error", (e) => fail(String(e.message)));
  // Errors three.js reports (shader compilation, lost context) go to console.error: show them too, so
  // that a page that draws nothing says why (and a test reading the page sees it).
  const consoleError = console.error.bind(console);
  console.error = (...args) => {
    fail(args.map(String).join(" "));
    consoleError(...args);
  };

  const data = JSON.parse(document.getElementById("motion-data").textContent);
  const frames = data.frames;
  const fps = data.fps;
  const parents = data.parents;
  const J = parents.length;
  const motions = data.motions.map((m) => ({ ...m, joints: Float32Array.from(m.joints, (v) => v / 1000) }));

  function joint(m, f, j, out) {
    const i = (f * J + j) * 3;
    return out.set(m.joints[i], m.joints[i + 1], m.joints[i + 2]);
  }

  // Bounds of every joint of every frame: where the floor and the camera go.
  const box = new THREE.Box3();
  const v = new THREE.Vector3();
  for (const m of motions) {
    for (let i = 0; i < m.joints.length; i += 3) box.expandByPoint(v.set(m.joints[i], m.joints[i + 1], m.joints[i + 2]));
  }
  const centre = box.getCenter(new THREE.Vector3());
  const extent = box.getSize(new THREE.Vector3());

  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true });
  } catch (e) {
    fail("WebGL is not available in this browser: " + e.message);
    return;
  }
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  document.getElementById("view").appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xf8f8f4);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8a80, 2.2));
  const sun = new THREE.DirectionalLight(0xffffff, 1.4);
  sun.position.set(3, 6, 4);
  scene.add(sun);

  // Floor: 0.5 m cells over the whole area the motions cover, and a 1 m bar as the scale, on a grid line
  // in front of the motions and left of them (placed in show(), as the camera target moves).
  const half = Math.ceil((Math.max(extent.x, extent.z) / 2 + 2) / 0.5) * 0.5;
  // Lines cut into 0.5 m pieces: a long line that passes beside the camera is dropped whole by some
  // software rasterisers (SwiftShader, headless browsers) instead of being clipped.
  const gx = Math.round(centre.x * 2) / 2;
  const gz = Math.round(centre.z * 2) / 2;
  const floor = [];
  for (let u = -half; u <= half; u += 0.5) {
    for (let w = -half; w < half; w += 0.5) {
      floor.push(gx + u, 0, gz + w, gx + u, 0, gz + w + 0.5, gx + w, 0, gz + u, gx + w + 0.5, 0, gz + u);
    }
  }
  const gridGeometry = new THREE.BufferGeometry();
  gridGeometry.setAttribute("position", new THREE.Float32BufferAttribute(floor, 3));
  scene.add(new THREE.LineSegments(gridGeometry, new THREE.LineBasicMaterial({ color: 0xbdbdb8 })));
  const bar = new THREE.Mesh(new THREE.CylinderGeometry(0.012, 0.012, 1, 8), new THREE.MeshBasicMaterial({ color: 0x1e1e1e }));
  bar.rotation.z = Math.PI / 2;
  scene.add(bar);
  const barLeft = Math.ceil(extent.x / 2 / 0.5) * 0.5 + 1.0;
  function placeBar(at) {
    bar.position.set(Math.round(at.x * 2) / 2 - barLeft, 0.012, Math.round(at.z * 2) / 2 + 1.0);
  }

  // One figure per motion: a sphere per joint, a cylinder per bone, in the motion's colour.
  const sphere = new THREE.SphereGeometry(1, 16, 12);
  const cylinder = new THREE.CylinderGeometry(1, 1, 1, 10);
  const contactMaterial = new THREE.MeshLambertMaterial({ color: CONTACT });
  const up = new THREE.Vector3(0, 1, 0);
  const a = new THREE.Vector3();
  const b = new THREE.Vector3();
  for (const m of motions) {
    m.material = new THREE.MeshLambertMaterial({ color: new THREE.Color(m.colour) });
    m.group = new THREE.Group();
    m.spheres = [];
    m.bones = [];
    for (let j = 0; j < J; j++) {
      const s = new THREE.Mesh(sphere, m.material);
      s.scale.setScalar(0.03);
      m.group.add(s);
      m.spheres.push(s);
      if (parents[j] >= 0) {
        const c = new THREE.Mesh(cylinder, m.material);
        m.group.add(c);
        m.bones.push([j, c]);
      }
    }
    scene.add(m.group);
  }

  // One skinned body per motion: its .glb (physmotion/io/gltf.py: capsules bound to the 22 joints, the motion
  // as a glTF animation at the page's rate) parsed by GLTFLoader, played by an AnimationMixer set to each
  // shown frame's time, moved along X by the motion's offset and drawn in its colour.
  const bodyBox = document.getElementById("body");
  const sticksBox = document.getElementById("sticks");
  function base64Bytes(text) {
    const raw = atob(text);
    const bytes = new Uint8Array(raw.length);
    for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
    return bytes.buffer;
  }
  const loader = new THREE.GLTFLoader();
  const bodies = Promise.all(motions.map((m) => loader.parseAsync(base64Bytes(m.glb), "").then((gltf) => {
    const material = new THREE.MeshLambertMaterial({ color: new THREE.Color(m.colour) });
    gltf.scene.traverse((o) => {
      if (o.isSkinnedMesh) {
        o.material = material;
        o.frustumCulled = false; // its bounds are those of the bind pose, not of where the motion has gone
      }
    });
    gltf.scene.position.x = m.offset;
    m.body = gltf.scene;
    m.mixer = new THREE.AnimationMixer(gltf.scene);
    m.mixer.clipAction(gltf.animations[0]).play();
    scene.add(gltf.scene);
  })));

  const legend = document.getElementById("legend");
  for (const m of motions) {
    const row = document.createElement("div");
    const swatch = document.createElement("span");
    swatch.className = "swatch";
    swatch.style.background = m.colour;
    row.append(swatch, document.createTextNode(m.label));
    legend.append(row);
  }
  const key = document.createElement("div");
  key.innerHTML = '<span class="swatch" style="background:#e600c8;border-radius:6px"></span>foot contact' +
    " &nbsp; grid 0.5 m, bar 1 m";
  legend.append(key);

  function pose(f) {
    for (const m of motions) {
      if (m.mixer) {
        m.mixer.setTime(f / fps); // a keyframe's time: the body takes that frame's pose exactly
        m.body.visible = bodyBox.checked;
      }
      for (let j = 0; j < J; j++) joint(m, f, j, m.spheres[j].position);
      for (const s of m.spheres) s.visible = sticksBox.checked;
      for (const [, c] of m.bones) c.visible = sticksBox.checked;
      for (const [j, c] of m.bones) {
        joint(m, f, parents[j], a);
        joint(m, f, j, b);
        const d = b.clone().sub(a);
        const length = d.length();
        c.position.copy(a).add(b).multiplyScalar(0.5);
        c.scale.set(0.018, Math.max(length, 1e-6), 0.018);
        if (length > 1e-9) c.quaternion.setFromUnitVectors(up, d.divideScalar(length));
      }
      data.foot_joints.forEach((j, i) => {
        const touching = (m.contacts[f] >> i) & 1;
        m.spheres[j].material = touching ? contactMaterial : m.material;
        m.spheres[j].scale.setScalar(touching ? (bodyBox.checked ? 0.055 : 0.045) : 0.03);
        if (touching) m.spheres[j].visible = true; // foot contacts are marked with or without the sticks
      });
    }
  }

  function rootCentre(f, out) {
    out.set(0, 0, 0);
    for (const m of motions) out.add(joint(m, f, 0, a));
    return out.divideScalar(motions.length).setY(0.9);
  }

  // Camera: front-right and above (as physmotion render), looking at the motions' roots at frame 0 from
  // far enough to see them all side by side; "follow" (on by default) keeps it on them as they travel.
  const camera = new THREE.PerspectiveCamera(40, 1, 0.05, 500);
  const distance = Math.max(5, 1.5 * extent.x + 2.5);
  const target = rootCentre(0, new THREE.Vector3());
  camera.position.copy(target).add(new THREE.Vector3(0.55, 0.45, 1.0).normalize().multiplyScalar(distance));
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.target.copy(target);
  controls.update();

  function resize() {
    const w = window.innerWidth;
    const h = window.innerHeight;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  window.addEventListener("resize", resize);
  resize();

  const reset = document.getElementById("reset");
  const resetFrames = new Map(motions.map((m) => [m, new Set(m.not_simulated || [])]));
  const play = document.getElementById("play");
  const scrub = document.getElementById("scrub");
  const readout = document.getElementById("time");
  const follow = document.getElementById("follow");
  scrub.max = String(frames - 1);
  const duration = (frames - 1) / fps;

  let playing = true;
  let time = 0;
  let last = null;
  let shown = -1;
  const followed = rootCentre(0, new THREE.Vector3());

  function frameAt(t) {
    return Math.min(frames - 1, Math.max(0, Math.round(t * fps)));
  }
  function setPlaying(on) {
    playing = on;
    last = null;
    play.textContent = on ? "Pause" : "Play";
  }
  function show(f) {
    if (f !== shown) {
      pose(f);
      shown = f;
      scrub.value = String(f);
      readout.textContent = `${(f / fps).toFixed(2)} / ${duration.toFixed(2)} s  (frame ${f + 1}/${frames})`;
      status.dataset.frame = String(f);
      // frames P did not simulate (a reset and the cross-fade before it), as physmotion render marks them
      const marked = motions.filter((m) => resetFrames.get(m).has(f)).map((m) => m.label);
      reset.textContent = marked.length ? `reset: not simulated (${marked.join(", ")})` : "";
      status.dataset.reset = marked.length ? "1" : "0";
    }
    if (follow.checked) {
      const now = rootCentre(f, new THREE.Vector3());
      const delta = now.clone().sub(followed);
      camera.position.add(delta);
      controls.target.add(delta);
      followed.copy(now);
    }
    placeBar(controls.target);
  }

  play.addEventListener("click", () => setPlaying(!playing));
  scrub.addEventListener("input", () => {
    setPlaying(false);
    time = Number(scrub.value) / fps;
  });
  follow.addEventListener("change", () => followed.copy(rootCentre(frameAt(time), new THREE.Vector3())));
  for (const box of [bodyBox, sticksBox]) box.addEventListener("change", () => { shown = -1; });

  const params = new URLSearchParams(window.location.search);
  follow.checked = params.get("follow") !== "0";
  bodyBox.checked = params.get("body") !== "0";
  sticksBox.checked = params.get("sticks") === "1";
  if (params.has("t")) {
    time = Math.min(duration, Math.max(0, Number(params.get("t")) || 0));
    setPlaying(false);
  }

  function tick(now) {
    if (playing) {
      if (last !== null) time = (time + (now - last) / 1000) % (duration + 1 / fps);
      last = now;
    }
    show(frameAt(time));
    controls.update();
    renderer.render(scene, camera);
    requestAnimationFrame(tick);
  }

  window.physmotionViewer = {
    setTime(t) { time = t; setPlaying(false); show(frameAt(time)); renderer.render(scene, camera); },
    play() { setPlaying(true); },
    pause() { setPlaying(false); },
    state() { return { time, frame: frameAt(time), frames, fps, playing }; },
  };
  // Ready once every body is loaded (parsing is asynchronous); the sticks play meanwhile.
  show(frameAt(time));
  renderer.render(scene, camera);
  requestAnimationFrame(tick);
  bodies.then(() => {
    shown = -1;
    show(frameAt(time));
    renderer.render(scene, camera);
    if (status.dataset.state === "loading") status.dataset.state = "ready";
  }, (e) => fail("a body could not be loaded: " + (e && e.message ? e.message : String(e))));
})();
