/*!
 * EezyViewer3D: 3D live view of a URDF robot for the gui_bridge web panel.
 * Built by nodes/gui_bridge/web/viewer3d/build.sh from viewer3d/src/viewer3d.js.
 *
 * Bundles:
 *   three.js          Copyright 2010-2026 three.js authors. MIT License.
 *   urdf-loader       Copyright Garrett Johnson (gkjohnson/urdf-loaders).
 *                     Apache License 2.0: http://www.apache.org/licenses/LICENSE-2.0
 */

// Only what is used is imported, so esbuild can tree-shake three.
import {
    AmbientLight,
    BoxGeometry,
    BufferGeometry,
    Color,
    CylinderGeometry,
    DirectionalLight,
    DoubleSide,
    EdgesGeometry,
    Float32BufferAttribute,
    GridHelper,
    Group,
    HemisphereLight,
    LatheGeometry,
    Line,
    LineBasicMaterial,
    LineSegments,
    Mesh,
    MeshBasicMaterial,
    MeshLambertMaterial,
    MeshPhongMaterial,
    Object3D,
    PerspectiveCamera,
    Points,
    PointsMaterial,
    Scene,
    Shape,
    ShapeGeometry,
    SphereGeometry,
    SRGBColorSpace,
    Vector2,
    Vector3,
    WebGLRenderer,
} from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import URDFLoader from 'urdf-loader/src/URDFLoader.js';

// ROS frames: z up, metres. The initial view suits an arm of about 0.3 m reach.
const HOME_TARGET = new Vector3(0.15, 0, 0.12);
const HOME_CAMERA = new Vector3(0.55, -0.45, 0.4);
const CELL = 0.05; // ground grid cell, metres
const TARGET_RADIUS = 0.008;
const REACHABLE = '#1a9850';
const UNREACHABLE = '#d73027';
const ENVELOPE_COLOR = '#4575b4';
const CUBE_SIDE = 0.025; // the physics twin's cube (libs/twin_model, CUBE_SIDE_M), metres
const CUBE_COLOR = '#d62728';
const STICK_COLOR = '#8a8a92';
const IDLE_MS = 1500; // stop the render loop this long after the last change
const MIN_FPS = 40; // adaptive resolution (software GL only) steps down below this
const RES_FLOOR = 0.6;

const _v = new Vector3();
const _up = new Vector3(0, 1, 0);

function webglError(detail) {
    return new Error('EezyViewer3D: WebGL 2 is not available in this browser' +
        (detail ? ' (' + detail + ')' : '') + '; use the 2D views.');
}

function makeRenderer(antialias) {
    try {
        return new WebGLRenderer({ canvas: document.createElement('canvas'), antialias });
    } catch (e) {
        throw webglError(e && e.message);
    }
}

const SOFTWARE_GL = /swiftshader|llvmpipe|softpipe|software|basic render/i;
function isSoftwareRenderer(gl) {
    let name = String(gl.getParameter(gl.RENDERER) || '');
    if (!SOFTWARE_GL.test(name) && /^webkit webgl$/i.test(name)) {
        const ext = gl.getExtension('WEBGL_debug_renderer_info'); // Chromium masks RENDERER
        if (ext) name = String(gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) || '');
    }
    return SOFTWARE_GL.test(name);
}

function disposeTree(obj) {
    obj.traverse((o) => {
        if (o.geometry) o.geometry.dispose();
        const m = o.material;
        if (Array.isArray(m)) m.forEach((x) => x.dispose());
        else if (m) m.dispose();
    });
}

function finite3(p) {
    return Array.isArray(p) && p.length >= 3 &&
        Number.isFinite(+p[0]) && Number.isFinite(+p[1]) && Number.isFinite(+p[2]);
}

function hasVisual(link) {
    return !!link && link.children.some((c) => c.isURDFVisual && c.children.length > 0);
}

// Longest sum of joint-origin distances from the root link to any link.
function chainReach(root) {
    let best = 0;
    const walk = (link, acc) => {
        best = Math.max(best, acc);
        for (const j of link.children) {
            if (!j.isURDFJoint) continue;
            const child = childLinkOf(j);
            if (child) walk(child, acc + (j.origPosition || j.position).length());
        }
    };
    walk(root, 0);
    return best;
}

function childLinkOf(joint) {
    return joint.children.find((c) => c.isURDFLink) || null;
}

// A cylinder in `parent`'s frame from its origin to `end`.
function makeStick(end, radius, material) {
    const len = end.length();
    const geom = new CylinderGeometry(radius, radius, len, 8, 1, false);
    const mesh = new Mesh(geom, material);
    mesh.position.copy(end).multiplyScalar(0.5);
    mesh.quaternion.setFromUnitVectors(_up, _v.copy(end).divideScalar(len));
    mesh.userData.eezyStick = true;
    return mesh;
}

function create(container, options = {}) {
    if (!container || typeof container.appendChild !== 'function') {
        throw new Error('EezyViewer3D.create: a container element is required');
    }
    const opts = Object.assign({ background: '#fbfbfd', antialias: 'auto', continuous: false, ignoreLimits: false }, options);

    // three.js needs WebGL 2; turn its context failure into one clear error for the caller.
    // On a software rasteriser (SwiftShader, llvmpipe) multisampling costs more than it gives:
    // with antialias "auto" (the default) the context is then recreated without it.
    let renderer = makeRenderer(opts.antialias !== false);
    const software = isSoftwareRenderer(renderer.getContext());
    if (software && opts.antialias === 'auto') {
        renderer.dispose();
        renderer.forceContextLoss();
        renderer = makeRenderer(false);
    }
    const antialias = renderer.getContext().getContextAttributes().antialias === true;
    const maxPixelRatio = software ? 1 : 2;
    const canvas = renderer.domElement;
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, maxPixelRatio));
    renderer.outputColorSpace = SRGBColorSpace;
    canvas.style.display = 'block';
    canvas.style.width = '100%';
    canvas.style.height = '100%';
    canvas.style.touchAction = 'none';
    container.appendChild(canvas);

    const scene = new Scene();
    scene.background = new Color(opts.background);

    const camera = new PerspectiveCamera(40, 1, 0.005, 50);
    camera.up.set(0, 0, 1); // ROS z-up
    camera.position.copy(HOME_CAMERA);
    scene.add(camera);

    const controls = new OrbitControls(camera, canvas);
    controls.target.copy(HOME_TARGET);
    controls.enableDamping = true;
    controls.dampingFactor = 0.15;
    controls.screenSpacePanning = true;
    controls.minDistance = 0.05;
    controls.maxDistance = 20;
    controls.update();

    // Lights: sky/ground fill from +z plus a key light that follows the camera.
    const hemi = new HemisphereLight(0xffffff, 0x8a8a80, 1.6);
    hemi.position.set(0, 0, 1);
    scene.add(hemi);
    scene.add(new AmbientLight(0xffffff, 0.35));
    const key = new DirectionalLight(0xffffff, 1.6);
    scene.add(key, key.target);

    // Takes obj (if any) out of the scene and frees its GPU resources; null, for the
    // variable that held it.
    function discard(obj) {
        if (obj) {
            scene.remove(obj);
            disposeTree(obj);
        }
        return null;
    }

    // Ground grid in the x-y plane and small axes at the origin.
    let grid = null;
    let gridSize = 0;
    function setGrid(size) {
        size = Math.max(1, Math.ceil(size));
        if (grid && size === gridSize) return;
        discard(grid);
        grid = new GridHelper(size, Math.round(size / CELL), 0xa8a8b4, 0xdcdce3);
        grid.rotation.x = Math.PI / 2; // GridHelper lies in x-z; ROS ground is x-y
        grid.position.z = -0.0005;
        grid.material.transparent = true;
        grid.material.opacity = 0.9;
        gridSize = size;
        scene.add(grid);
    }
    setGrid(1);

    const axes = new Group();
    function setAxes(len) {
        disposeTree(axes);
        axes.clear();
        const cols = [0xd73027, 0x1a9850, 0x2166ac];
        for (let i = 0; i < 3; i++) {
            const g = new BufferGeometry();
            const end = [0, 0, 0];
            end[i] = len;
            g.setAttribute('position', new Float32BufferAttribute([0, 0, 0, ...end], 3));
            axes.add(new Line(g, new LineBasicMaterial({ color: cols[i] })));
        }
    }
    setAxes(0.08);
    scene.add(axes);

    // Target marker with a faint drop line to the ground.
    const target = new Group();
    const targetMat = new MeshPhongMaterial({ color: REACHABLE, shininess: 60 });
    const targetBall = new Mesh(new SphereGeometry(TARGET_RADIUS, 24, 16), targetMat);
    const dropGeom = new BufferGeometry();
    dropGeom.setAttribute('position', new Float32BufferAttribute([0, 0, 0, 0, 0, 0], 3));
    const dropMat = new LineBasicMaterial({ color: REACHABLE, transparent: true, opacity: 0.45 });
    const drop = new Line(dropGeom, dropMat);
    drop.frustumCulled = false;
    target.add(targetBall, drop);
    target.visible = false;
    scene.add(target);

    // The physics twin's cube: a 25 mm red box with dark edges, hidden until posed, with a
    // faint drop line from its centre to the ground (the stand it may sit on is not drawn).
    const cube = new Group();
    const cubeGeom = new BoxGeometry(CUBE_SIDE, CUBE_SIDE, CUBE_SIDE);
    cube.add(new Mesh(cubeGeom, new MeshPhongMaterial({ color: CUBE_COLOR, shininess: 30 })));
    cube.add(new LineSegments(new EdgesGeometry(cubeGeom), new LineBasicMaterial({ color: 0x5a0f0f })));
    cube.visible = false;
    scene.add(cube);
    const cubeDropGeom = new BufferGeometry();
    cubeDropGeom.setAttribute('position', new Float32BufferAttribute([0, 0, 0, 0, 0, 0], 3));
    const cubeDrop = new Line(cubeDropGeom, new LineBasicMaterial({ color: CUBE_COLOR, transparent: true, opacity: 0.45 }));
    cubeDrop.frustumCulled = false;
    cubeDrop.visible = false;
    scene.add(cubeDrop);

    let robot = null;
    let envelope = null;
    const jointValues = Object.create(null); // last value per joint name, re-applied to a new robot
    let disposed = false;
    let userMoved = false;

    // ---- render loop -------------------------------------------------------------------------
    let raf = 0;
    let lastWake = 0;
    let frames = 0;
    const stamps = []; // render times of the last second
    let contextLost = false;

    // Software rasterisers only: while the loop runs flat out but renders under MIN_FPS, step the
    // internal resolution down (never below RES_FLOOR; never back up) so the view stays live.
    const adaptive = software && opts.adaptiveResolution !== false;
    let resScale = 1;
    let awakeSince = 0;
    let lastResChange = 0;
    let sleeping = true;

    function wake() {
        if (disposed) return;
        lastWake = performance.now();
        if (sleeping) { sleeping = false; awakeSince = lastWake; }
        if (!raf) raf = requestAnimationFrame(frame);
    }

    function adapt(now) {
        if (!adaptive || resScale <= RES_FLOOR || document.hidden) return;
        if (now - awakeSince < 1500 || now - lastResChange < 1500 || stamps.length >= MIN_FPS) return;
        resScale = Math.max(RES_FLOOR, Math.round((resScale - 0.1) * 100) / 100);
        lastResChange = now;
        resize();
    }

    function frame(now) {
        raf = 0;
        if (disposed) return;
        const moving = controls.update();
        if (moving) lastWake = now;
        key.position.copy(camera.position);
        key.target.position.copy(controls.target);
        if (!contextLost) {
            renderer.render(scene, camera);
            frames++;
            stamps.push(now);
        }
        while (stamps.length && stamps[0] <= now - 1000) stamps.shift();
        adapt(now);
        // controls' 'change' may already have re-armed the loop through wake().
        if (!raf && (opts.continuous || now - lastWake < IDLE_MS)) raf = requestAnimationFrame(frame);
        if (!raf) sleeping = true;
    }

    controls.addEventListener('start', () => { userMoved = true; wake(); });
    controls.addEventListener('change', wake);

    const onLost = (e) => { e.preventDefault(); contextLost = true; };
    const onRestored = () => { contextLost = false; wake(); };
    canvas.addEventListener('webglcontextlost', onLost);
    canvas.addEventListener('webglcontextrestored', onRestored);

    // ---- size ----------------------------------------------------------------------------------
    function resize() {
        if (disposed) return;
        const w = container.clientWidth;
        const h = container.clientHeight;
        if (w < 1 || h < 1) return;
        renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, maxPixelRatio) * resScale);
        renderer.setSize(w, h, false);
        camera.aspect = w / h;
        camera.updateProjectionMatrix();
        wake();
    }
    let ro = null;
    if (typeof ResizeObserver === 'function') {
        ro = new ResizeObserver(() => resize());
        ro.observe(container);
    } else {
        window.addEventListener('resize', resize);
    }

    // ---- view framing -------------------------------------------------------------------------
    let scale = 1; // robot size relative to a ~0.3 m reach arm
    let frameCenter = HOME_TARGET.clone();
    function resetView() {
        if (scale <= 1) {
            controls.target.copy(HOME_TARGET);
            camera.position.copy(HOME_CAMERA);
        } else {
            controls.target.copy(frameCenter);
            camera.position.copy(HOME_CAMERA).sub(HOME_TARGET).multiplyScalar(scale).add(frameCenter);
        }
        camera.near = 0.005 * scale;
        camera.far = 50 * scale;
        camera.updateProjectionMatrix();
        controls.update();
        userMoved = false;
        wake();
    }

    // ---- robot --------------------------------------------------------------------------------
    function setRobot(urdfText) {
        if (disposed) return;
        if (urdfText == null || urdfText === '') { robot = discard(robot); wake(); return; }
        const doc = new DOMParser().parseFromString(String(urdfText), 'text/xml');
        const err = doc.getElementsByTagName('parsererror')[0];
        if (err) {
            const msg = (err.querySelector('div') || err).textContent.trim().split('\n')[0];
            throw new Error('EezyViewer3D.setRobot: invalid URDF XML: ' + msg);
        }
        if (!doc.documentElement || doc.documentElement.nodeName !== 'robot') {
            throw new Error('EezyViewer3D.setRobot: no <robot> element');
        }

        const loader = new URDFLoader();
        loader.parseVisual = true;
        loader.parseCollision = false;
        // Our URDFs use primitives only: never fetch meshes.
        loader.loadMeshCb = (path, manager, material, done) => done(null, new Error('mesh loading disabled: ' + path));
        const r = loader.parse(doc);
        if (!r) throw new Error('EezyViewer3D.setRobot: URDF parse failed');

        discard(robot);
        robot = r;

        // urdf-loader stores URDF rgba as linear; URDF colours are meant as display (sRGB) values.
        const seen = new Set();
        robot.traverse((o) => {
            const mats = Array.isArray(o.material) ? o.material : (o.material ? [o.material] : []);
            for (const m of mats) {
                if (seen.has(m) || !m.color) continue;
                seen.add(m);
                m.color.setRGB(m.color.r, m.color.g, m.color.b, SRGBColorSpace);
            }
        });

        // Scale, independent of the pose: the longest chain of joint offsets from the root.
        const reach = Math.max(0.05, chainReach(robot));

        // Stick figure: a thin grey cylinder from the parent frame origin to the child frame origin
        // for every joint whose parent or child link has no visual, and a ball at such a child.
        const stickR = Math.min(0.02, Math.max(0.002, reach * 0.008));
        const stickMat = new MeshLambertMaterial({ color: STICK_COLOR });
        const ballGeom = new SphereGeometry(stickR * 1.8, 16, 10);
        for (const name in robot.joints) {
            const joint = robot.joints[name];
            const parent = joint.parent;
            const child = childLinkOf(joint);
            if (!parent || !parent.isURDFLink) continue;
            const parentVis = hasVisual(parent);
            const childVis = hasVisual(child);
            if (parentVis && childVis) continue;
            const end = (joint.origPosition || joint.position).clone();
            if (end.length() > 1e-6) parent.add(makeStick(end, stickR, stickMat));
            if (child && !childVis) {
                const ball = new Mesh(ballGeom, stickMat);
                ball.userData.eezyStick = true;
                child.add(ball);
            }
        }
        if (!hasVisual(robot) && Object.keys(robot.joints).length === 0) {
            robot.add(new Mesh(ballGeom, stickMat)); // a lone link: at least show a dot
        }

        for (const name in robot.joints) robot.joints[name].ignoreLimits = !!opts.ignoreLimits;
        scene.add(robot);
        applyJoints(jointValues);

        // Framing and grid follow the robot's scale (the home view suits <= ~0.6 m of chain);
        // a camera the user has moved is kept.
        scale = reach > 0.6 ? reach / 0.42 : 1;
        frameCenter = new Vector3(0, 0, 0.35 * reach);
        setGrid(scale <= 1 ? 1 : 2.4 * reach);
        setAxes(0.08 * scale);
        targetBall.scale.setScalar(scale); // 8 mm on an arm of ~0.3 m reach
        if (!userMoved) resetView();
        wake();
    }

    function applyJoints(values) {
        let n = 0;
        if (!robot) return n;
        for (const name in values) {
            const joint = robot.joints[name];
            const val = +values[name];
            if (!joint || !Number.isFinite(val)) continue;
            joint.setJointValue(val);
            n++;
        }
        return n;
    }

    function setJoints(values) {
        if (disposed || !values || typeof values !== 'object') return 0;
        for (const name in values) {
            const val = +values[name];
            if (Number.isFinite(val)) jointValues[name] = val;
        }
        const n = applyJoints(values);
        wake();
        return n;
    }

    // ---- target -------------------------------------------------------------------------------
    function setTarget(p, reachable) {
        if (disposed) return;
        if (!finite3(p)) {
            target.visible = false;
        } else {
            const x = +p[0], y = +p[1], z = +p[2];
            targetBall.position.set(x, y, z);
            const pos = dropGeom.attributes.position;
            pos.setXYZ(0, x, y, z);
            pos.setXYZ(1, x, y, 0);
            pos.needsUpdate = true;
            const c = reachable ? REACHABLE : UNREACHABLE;
            targetMat.color.set(c);
            dropMat.color.set(c);
            target.visible = true;
        }
        wake();
    }

    // ---- the twin's cube ----------------------------------------------------------------------
    // p: [x, y, z] in the robot's root frame (base_link), q: [x, y, z, w] (default: no turn);
    // null (or a p that is not finite) hides it.
    function setCube(p, q) {
        if (disposed) return;
        if (!finite3(p)) {
            cube.visible = false;
            cubeDrop.visible = false;
        } else {
            cube.position.set(+p[0], +p[1], +p[2]);
            const drop = cubeDropGeom.attributes.position;
            drop.setXYZ(0, +p[0], +p[1], +p[2]);
            drop.setXYZ(1, +p[0], +p[1], 0);
            drop.needsUpdate = true;
            cubeDrop.visible = true;
            const ok = Array.isArray(q) && q.length === 4 && q.every((v) => Number.isFinite(+v));
            if (ok) cube.quaternion.set(+q[0], +q[1], +q[2], +q[3]).normalize();
            else cube.quaternion.identity();
            cube.visible = true;
        }
        wake();
    }

    // The cube as drawn: {position, quaternion, side}, or null while hidden.
    function cubeState() {
        if (!cube.visible) return null;
        const p = cube.position, q = cube.quaternion;
        return { position: [p.x, p.y, p.z], quaternion: [q.x, q.y, q.z, q.w], side: CUBE_SIDE };
    }

    // ---- envelope -----------------------------------------------------------------------------
    function latheEnvelope(env) {
        const prof = (env.profile || []).filter((p) => Array.isArray(p) && Number.isFinite(+p[0]) && Number.isFinite(+p[1]))
            .map((p) => new Vector2(Math.max(0, +p[0]), +p[1]));
        if (prof.length < 2) return null;
        const first = prof[0], last = prof[prof.length - 1];
        if (prof.length > 2 && (first.x !== last.x || first.y !== last.y)) prof.push(first.clone());

        let y0 = -Math.PI, y1 = Math.PI;
        if (Array.isArray(env.yaw) && Number.isFinite(+env.yaw[0]) && Number.isFinite(+env.yaw[1])) {
            y0 = Math.min(+env.yaw[0], +env.yaw[1]);
            y1 = Math.max(+env.yaw[0], +env.yaw[1]);
        }
        const span = Math.min(y1 - y0, 2 * Math.PI);
        if (span <= 0) return null;
        const full = span >= 2 * Math.PI - 1e-6;

        const group = new Group();
        const fill = new MeshBasicMaterial({
            color: ENVELOPE_COLOR, transparent: true, opacity: 0.12,
            depthWrite: false, side: DoubleSide,
            forceSinglePass: true, // one pass, not three's back-then-front pair: half the fill cost
        });
        const edge = new LineBasicMaterial({ color: ENVELOPE_COLOR, transparent: true, opacity: 0.35, depthWrite: false });

        // LatheGeometry revolves (r, h) about +Y as (r sin(phi), h, r cos(phi)). Rotating +90 deg
        // about X maps that to (r sin(phi), -r cos(phi), h), which is ROS yaw = phi - pi/2.
        const segs = Math.max(6, Math.ceil(72 * span / (2 * Math.PI)));
        const lathe = new LatheGeometry(prof, segs, y0 + Math.PI / 2, span);
        const shell = new Mesh(lathe, fill);
        shell.rotation.x = Math.PI / 2;
        shell.renderOrder = 1;
        const outline = new LineSegments(new EdgesGeometry(lathe, 25), edge);
        outline.rotation.x = Math.PI / 2;
        group.add(shell, outline);

        // A partial revolution gets the profile as end caps.
        if (!full && prof.length >= 3) {
            const shapeGeom = new ShapeGeometry(new Shape(prof.slice(0, -1)));
            for (const yaw of [y0, y1]) {
                const holder = new Object3D();
                holder.rotation.z = yaw;
                const cap = new Mesh(shapeGeom, fill);
                cap.rotation.x = Math.PI / 2; // shape (r, z) in x-y -> (r, 0, z)
                cap.renderOrder = 1;
                holder.add(cap);
                group.add(holder);
            }
        }
        return group;
    }

    function pointsEnvelope(env) {
        const arr = [];
        for (const p of env.points || []) if (finite3(p)) arr.push(+p[0], +p[1], +p[2]);
        if (!arr.length) return null;
        const g = new BufferGeometry();
        g.setAttribute('position', new Float32BufferAttribute(arr, 3));
        const m = new PointsMaterial({
            color: ENVELOPE_COLOR, size: 3, sizeAttenuation: false,
            transparent: true, opacity: 0.35, depthWrite: false,
        });
        const pts = new Points(g, m);
        pts.renderOrder = 1;
        return pts;
    }

    function setEnvelope(env) {
        if (disposed) return;
        envelope = discard(envelope);
        if (env && env.kind === 'lathe') envelope = latheEnvelope(env);
        else if (env && env.kind === 'points') envelope = pointsEnvelope(env);
        if (envelope) scene.add(envelope);
        wake();
    }

    // ---- stats / dispose ----------------------------------------------------------------------
    function stats() {
        const now = performance.now();
        let n = 0;
        for (let i = stamps.length - 1; i >= 0 && stamps[i] > now - 1000; i--) n++;
        return { fps: n, frames, antialias, software, pixelRatio: renderer.getPixelRatio() };
    }

    function dispose() {
        if (disposed) return;
        disposed = true;
        if (raf) cancelAnimationFrame(raf);
        raf = 0;
        if (ro) ro.disconnect(); else window.removeEventListener('resize', resize);
        canvas.removeEventListener('webglcontextlost', onLost);
        canvas.removeEventListener('webglcontextrestored', onRestored);
        controls.dispose();
        robot = discard(robot);
        envelope = discard(envelope);
        disposeTree(scene);
        renderer.dispose();
        renderer.forceContextLoss();
        if (canvas.parentNode) canvas.parentNode.removeChild(canvas);
    }

    resize();
    wake();

    return {
        setRobot,
        setJoints,
        setTarget,
        setCube,
        cube: cubeState,
        setEnvelope,
        resize,
        resetView,
        stats,
        dispose,
        get canvas() { return canvas; },
        get robot() { return robot; },
    };
}

const api = { create, version: '1.0.0' };
if (typeof window !== 'undefined') window.EezyViewer3D = api;
