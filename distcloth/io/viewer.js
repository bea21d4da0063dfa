// distcloth's result viewer: the frames embedded in the page (io/viewer.py
// writes DATA), drawn with three.js, orbit controls, a time slider and play.
// The frame to show first comes from the URL: page.html#frame=12.
// #status tells a test (or a puzzled user) whether the page works:
// "ok frame=K frames=N" after each drawn frame, "error: ..." otherwise.
(function () {
  "use strict";
  var status = document.getElementById("status");
  function fail(message) {
    status.textContent = "error: " + message;
    status.className = "error";
  }
  window.addEventListener("error", function (e) { fail(e.message || String(e)); });

  function decode(b64, Type) {
    var bin = atob(b64), bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new Type(bytes.buffer);
  }

  var DATA = JSON.parse(document.getElementById("data").textContent);
  var nFrames = DATA.times.length, n = DATA.vertices;
  var frames = decode(DATA.positions, Float32Array);       // nFrames * n * 3
  var renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
  if (!renderer.getContext()) throw new Error("no WebGL");
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(window.innerWidth, window.innerHeight);
  renderer.setClearColor(0xf4f4f0);
  document.body.insertBefore(renderer.domElement, document.body.firstChild);

  var scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8888aa, 0.75));
  var sun = new THREE.DirectionalLight(0xffffff, 0.6);
  sun.position.set(1, -2, 3);
  scene.add(sun);

  function surface(nVertices, triangles, color, opacity) {
    var g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(nVertices * 3), 3));
    g.setIndex(new THREE.BufferAttribute(triangles, 1));
    var m = new THREE.MeshPhongMaterial({color: color, side: THREE.DoubleSide, shininess: 8,
                                         transparent: opacity < 1, opacity: opacity,
                                         polygonOffset: true, polygonOffsetFactor: 1});
    var mesh = new THREE.Mesh(g, m);
    scene.add(mesh);
    return mesh;
  }
  function place(mesh, rows, k, count) {
    var attr = mesh.geometry.attributes.position;
    attr.array.set(rows.subarray(k * count * 3, (k + 1) * count * 3));
    attr.needsUpdate = true;
    mesh.geometry.computeVertexNormals();
    mesh.geometry.computeBoundingSphere();
  }

  var cloth = surface(n, decode(DATA.triangles, Uint32Array), 0xd0603a, 1.0);
  var bodies = DATA.colliders.map(function (c) {
    return {rows: decode(c.positions, Float32Array), moving: c.moving, count: c.vertices,
            mesh: surface(c.vertices, decode(c.triangles, Uint32Array), 0x8a9bb0, 0.85)};
  });

  // the camera frames the cloth over all frames (colliders such as a floor
  // plane can be much larger than the scene of interest)
  var lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (var i = 0; i < frames.length; i += 3) {
    for (var a = 0; a < 3; a++) {
      var v = frames[i + a];
      if (v < lo[a]) lo[a] = v;
      if (v > hi[a]) hi[a] = v;
    }
  }
  var center = new THREE.Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
  var size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], 1e-3);
  var camera = new THREE.PerspectiveCamera(40, window.innerWidth / window.innerHeight,
                                           size / 100, size * 100);
  camera.up.set(0, 0, 1);           // the simulator's z is up
  camera.position.set(center.x + 1.2 * size, center.y - 1.8 * size, center.z + 0.9 * size);
  var controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.target.copy(center);
  controls.update();

  var slider = document.getElementById("slider"), label = document.getElementById("label");
  slider.max = String(nFrames - 1);
  var current = 0;
  function render() { renderer.render(scene, camera); }
  function show(k) {
    k = Math.max(0, Math.min(nFrames - 1, k | 0));
    current = k;
    place(cloth, frames, k, n);
    bodies.forEach(function (b) { place(b.mesh, b.rows, b.moving ? k : 0, b.count); });
    label.textContent = "frame " + k + " / " + (nFrames - 1) + "   t = " +
      DATA.times[k].toFixed(3) + " s";
    render();
    if (status.className !== "error") status.textContent = "ok frame=" + k + " frames=" + nFrames;
  }
  slider.addEventListener("input", function () { show(+slider.value); });
  controls.addEventListener("change", render);
  window.addEventListener("resize", function () {
    camera.aspect = window.innerWidth / window.innerHeight;
    camera.updateProjectionMatrix();
    renderer.setSize(window.innerWidth, window.innerHeight);
    render();
  });

  var playing = null, play = document.getElementById("play");
  play.addEventListener("click", function () {
    if (playing) { clearInterval(playing); playing = null; play.textContent = "play"; return; }
    play.textContent = "pause";
    playing = setInterval(function () {
      slider.value = String((current + 1) % nFrames);
      slider.dispatchEvent(new Event("input"));
    }, 1000 / DATA.fps);
  });

  function fromHash() {
    var m = /frame=(-?\d+)/.exec(window.location.hash);
    var k = m ? parseInt(m[1], 10) : 0;
    // through the slider, as a user would move it
    slider.value = String(k < 0 ? nFrames + k : k);
    slider.dispatchEvent(new Event("input"));
  }
  window.addEventListener("hashchange", fromHash);
  fromHash();
})();
