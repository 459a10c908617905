// The radiosity toolkit's browser viewer (written by `radiosity view SCENE --web DIR` with index.html, the wasm
// build of the device core, the table and scene.json).
//
// Every animation frame: the light groups and materials the user changed are applied (rft_set_light,
// rft_set_reflectance: their work units are outside the budget, as on the device), then the core's bounded
// shooting runs for at most the chosen budget (rft_step), and the patches are drawn flat with the project's tone
// map (Reinhard with a white point, sRGB). The error against the exact f64 answer is plotted against the work
// spent since the last change.
//
// The page opens at the scene's camera (scene.json: the camera `radiosity render` uses) with the tone map of
// `radiosity render --mode flat` through it, so once converged at the default intensities its first view is that
// picture, up to the table's quantization and 8-bit rounding.
//
// URL parameters: `budget=N` (exact work units per frame until the slider moves), `tolerance=T` (convergence,
// relative to the table's unit light power), `size=WxH` (the canvas's size in CSS pixels instead of the window's
// remainder; tests compare it with a render of that size).
//
// For tests, `window.viewer` exposes the state: `ready`, `error`, `stats` (frames, largest budget overrun),
// `frames` (the last frames' budget and units used), `converged`, `radiosity()`, `intensity(g)` and
// `reflectance(m)` (what the solver was given), and `setLight(g, s)`. The controls carry `data-group` (intensity
// sliders), `data-group-colour` (colour inputs) and `data-material` with `data-channel` (reflectance sliders).

const LUMINANCE = [0.2126, 0.7152, 0.0722];
const params = new URLSearchParams(location.search);
// Convergence tolerance relative to the table's unit light power (as the relight scripts give it).
const TOLERANCE = Number(params.get("tolerance") ?? "1e-5");
// Frames kept in window.viewer.frames.
const KEEP_FRAMES = 2000;

const viewer = {
    ready: false,
    error: undefined,
    converged: false,
    budget: 0,
    frames: [],
    stats: { frames: 0, overBudget: 0, maxUsed: 0, workSinceChange: 0 },
};
window.viewer = viewer;

const $ = (id) => document.getElementById(id);

function fail(message) {
    viewer.error = String(message);
    $("status").textContent = `error: ${message}`;
    console.error(message);
}

async function fetchOk(name) {
    const r = await fetch(name);
    if (!r.ok) {
        throw new Error(`${name}: HTTP ${r.status}`);
    }
    return r;
}

// --- small matrix helpers (column-major 4x4, as WebGL takes them) ---
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const norm = (a) => scale(a, 1 / Math.hypot(a[0], a[1], a[2]));

function lookAt(eye, target, up) {
    const f = norm(sub(target, eye));
    const s = norm(cross(f, up));
    const u = cross(s, f);
    return [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
        -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
}

function perspective(fovyDeg, aspect, near, far) {
    const t = 1 / Math.tan((fovyDeg * Math.PI) / 360);
    return [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1,
        0, 0, (2 * far * near) / (near - far), 0];
}

function multiply(a, b) {
    const out = new Array(16).fill(0);
    for (let c = 0; c < 4; c++) {
        for (let r = 0; r < 4; r++) {
            for (let k = 0; k < 4; k++) {
                out[4 * c + r] += a[4 * k + r] * b[4 * c + k];
            }
        }
    }
    return out;
}

// --- WebGL2 ---
const VERTEX = `#version 300 es
in vec3 position;
in vec3 radiosity;
uniform mat4 viewProjection;
out vec3 vRadiosity;
void main() {
    vRadiosity = radiosity;
    gl_Position = viewProjection * vec4(position, 1.0);
}`;

// The project's tone map (host/src/picture/tonemap.rs): exposure, Reinhard's operator with a white point applied
// to luminance, channels clipped at 1, then sRGB encoding.
const FRAGMENT = `#version 300 es
precision highp float;
in vec3 vRadiosity;
uniform float exposure;
uniform float white;
out vec4 colour;
float srgb(float v) {
    return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}
void main() {
    vec3 c = max(vRadiosity, 0.0) * exposure;
    float l = dot(c, vec3(${LUMINANCE.join(", ")}));
    vec3 shown = vec3(0.0);
    if (l > 0.0) {
        float ld = l * (1.0 + l / (white * white)) / (1.0 + l);
        shown = min(c * (ld / l), 1.0);
    }
    colour = vec4(srgb(shown.r), srgb(shown.g), srgb(shown.b), 1.0);
}`;

function compile(gl, type, source) {
    const s = gl.createShader(type);
    gl.shaderSource(s, source);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) {
        throw new Error(`shader: ${gl.getShaderInfoLog(s)}`);
    }
    return s;
}

function program(gl) {
    const p = gl.createProgram();
    gl.attachShader(p, compile(gl, gl.VERTEX_SHADER, VERTEX));
    gl.attachShader(p, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) {
        throw new Error(`program: ${gl.getProgramInfoLog(p)}`);
    }
    return p;
}

// Fan-triangulates every patch polygon, each triangle wound counter-clockwise around the patch's normal (so back
// faces can be culled: from outside a closed room one sees into it, as the project's pictures do). Returns the
// triangle vertex positions and the patch of each vertex.
function triangulate(scene) {
    const positions = [];
    const patchOf = [];
    const v = (k) => [scene.vertices[3 * k], scene.vertices[3 * k + 1], scene.vertices[3 * k + 2]];
    for (let i = 0; i < scene.patches; i++) {
        const start = scene.polygon_start[i];
        const end = scene.polygon_start[i + 1];
        const n = [scene.normal[3 * i], scene.normal[3 * i + 1], scene.normal[3 * i + 2]];
        for (let k = start + 1; k + 1 < end; k++) {
            let tri = [v(start), v(k), v(k + 1)];
            if (dot(cross(sub(tri[1], tri[0]), sub(tri[2], tri[0])), n) < 0) {
                tri = [tri[0], tri[2], tri[1]];
            }
            for (const p of tri) {
                positions.push(...p);
                patchOf.push(i);
            }
        }
    }
    return { positions: new Float32Array(positions), patchOf: Uint32Array.from(patchOf) };
}

// --- the page ---
async function main() {
    const [scene, table, wasm] = await Promise.all([
        fetchOk("scene.json").then((r) => r.json()),
        fetchOk("scene.rft").then((r) => r.arrayBuffer()),
        fetchOk("radiosity_web.wasm").then((r) => r.arrayBuffer()),
    ]);
    const { instance } = await WebAssembly.instantiate(wasm, {});
    const w = instance.exports;
    const message = () =>
        new TextDecoder().decode(new Uint8Array(w.memory.buffer, w.rft_message(), w.rft_message_len()));
    const at = w.rft_table_buffer(table.byteLength);
    new Uint8Array(w.memory.buffer, at, table.byteLength).set(new Uint8Array(table));
    if (w.rft_load(TOLERANCE) !== 0) {
        throw new Error(`loading the table: ${message()}`);
    }
    const n = w.rft_patch_count();
    const groups = w.rft_group_count();
    const materials = w.rft_material_count();
    if (n !== scene.patches || groups !== scene.groups.length || materials !== scene.materials.length) {
        throw new Error(`table (${n} patches, ${groups} groups, ${materials} materials) and scene.json ` +
            `(${scene.patches}, ${scene.groups.length}, ${scene.materials.length}) differ`);
    }

    // State the user edits: per group a scale of its default intensity, per material a reflectance.
    const intensityScale = new Array(groups).fill(1);
    const tableReflectance = [];
    for (let m = 0; m < materials; m++) {
        tableReflectance.push([0, 1, 2].map((c) => w.rft_table_reflectance(m, c)));
    }
    const reflectance = tableReflectance.map((r) => r.slice());
    const pendingLights = new Set();
    const pendingMaterials = new Set();

    // Sliders.
    const slider = (parent, name, min, max, step, value, onInput) => {
        const label = document.createElement("label");
        const span = document.createElement("span");
        span.textContent = name;
        span.title = name;
        const input = document.createElement("input");
        Object.assign(input, { type: "range", min, max, step, value });
        const out = document.createElement("output");
        out.textContent = Number(value).toFixed(2);
        input.addEventListener("input", () => {
            out.textContent = Number(input.value).toFixed(2);
            onInput(Number(input.value));
        });
        label.append(span, input, out);
        parent.append(label);
        return input;
    };
    const lightSliders = scene.groups.map((g, k) =>
        slider($("groups"), g.name, 0, 3, 0.01, 1, (v) => {
            intensityScale[k] = v;
            pendingLights.add(k);
        }));
    lightSliders.forEach((s, k) => { s.dataset.group = String(k); });
    // A colour per group: its channels (decoded from sRGB to linear) multiply the default intensity.
    const srgbDecode = (v) => (v <= 0.04045 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4);
    const lightColour = scene.groups.map(() => [1, 1, 1]);
    lightSliders.forEach((s, k) => {
        const input = document.createElement("input");
        Object.assign(input, { type: "color", value: "#ffffff", title: `${scene.groups[k].name}: colour` });
        input.dataset.groupColour = String(k);
        input.addEventListener("input", () => {
            const hex = input.value.slice(1);
            lightColour[k] = [0, 2, 4].map((at) => srgbDecode(parseInt(hex.slice(at, at + 2), 16) / 255));
            pendingLights.add(k);
        });
        s.parentElement.append(input);
    });
    // Intensity of group g, RGB: default x slider x colour.
    const intensityOf = (g) => scene.groups[g].default_intensity.map((v, c) => v * intensityScale[g] * lightColour[g][c]);
    scene.materials.forEach((mat, m) => {
        const box = document.createElement("div");
        const title = document.createElement("div");
        title.className = "note";
        title.textContent = mat.name;
        box.append(title);
        ["R", "G", "B"].forEach((c, k) => {
            const input = slider(box, c, 0, 0.95, 0.01, reflectance[m][k], (v) => {
                reflectance[m][k] = v;
                pendingMaterials.add(m);
            });
            input.dataset.material = String(m);
            input.dataset.channel = String(k);
        });
        $("materials").append(box);
    });

    // Budget: a log-scale slider of work units per frame, with the Cortex-M4F cost of that many units.
    const cost = scene.cost;
    // `?budget=N` sets an exact budget (the slider snaps to its steps) until the slider is moved.
    let exactBudget = params.has("budget") ? Math.max(1, Math.round(Number(params.get("budget")))) : undefined;
    const readBudget = (event) => {
        if (event !== undefined) {
            exactBudget = undefined;
        }
        viewer.budget = exactBudget ?? Math.max(1, Math.round(10 ** Number($("budget").value)));
        const instr = cost.overhead + cost.per_unit * viewer.budget;
        const bound = cost.bound_overhead + cost.bound_per_unit * viewer.budget;
        $("budget-out").textContent = String(viewer.budget);
        $("budget-cost").textContent =
            `about ${instr.toExponential(2)} Cortex-M4F instructions per frame (at most ` +
            `${bound.toExponential(2)}; ${(instr / 100e3).toFixed(2)} ms at 100 MHz), from the ${cost.build} ` +
            `model of firmware-sim/COST.md: ${cost.overhead} + ${cost.per_unit} per unit (light-change units ` +
            `come on top)`;
    };
    if (exactBudget !== undefined) {
        $("budget").value = String(Math.log10(exactBudget));
    }
    $("budget").addEventListener("input", readBudget);
    readBudget();

    // The exact answer for the current intensities (valid while the reflectances are the scene's).
    const exact = new Float64Array(3 * n);
    const reflectanceIsTable = () =>
        reflectance.every((r, m) => r.every((v, c) => v === tableReflectance[m][c]));
    const updateExact = () => {
        exact.set(scene.b_static);
        for (let g = 0; g < groups; g++) {
            const intensity = intensityOf(g);
            const t = scene.t[g];
            for (let k = 0; k < 3 * n; k++) {
                exact[k] += intensity[k % 3] * t[k];
            }
        }
    };
    updateExact();
    const relativeError = (b) => {
        let num = 0;
        let den = 0;
        for (let i = 0; i < n; i++) {
            let d2 = 0;
            let r2 = 0;
            for (let c = 0; c < 3; c++) {
                d2 += (b[3 * i + c] - exact[3 * i + c]) ** 2;
                r2 += exact[3 * i + c] ** 2;
            }
            num += scene.area[i] * d2;
            den += scene.area[i] * r2;
        }
        // Relative to nothing when the exact answer is black (every light off): no error to show.
        return den > 0 ? Math.sqrt(num / den) : undefined;
    };

    // Geometry.
    const canvas = $("view");
    const size = /^(\d+)x(\d+)$/.exec(params.get("size") ?? "");
    if (size) {
        Object.assign(canvas.style, { flex: "none", width: `${size[1]}px`, height: `${size[2]}px` });
    }
    const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
    if (!gl) {
        throw new Error("this browser has no WebGL2");
    }
    const prog = program(gl);
    const mesh = triangulate(scene);
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const positionBuffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, positionBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, mesh.positions, gl.STATIC_DRAW);
    const positionAttr = gl.getAttribLocation(prog, "position");
    gl.enableVertexAttribArray(positionAttr);
    gl.vertexAttribPointer(positionAttr, 3, gl.FLOAT, false, 0, 0);
    const vertexRadiosity = new Float32Array(mesh.positions.length);
    const radiosityBuffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, radiosityBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, vertexRadiosity, gl.DYNAMIC_DRAW);
    const radiosityAttr = gl.getAttribLocation(prog, "radiosity");
    gl.enableVertexAttribArray(radiosityAttr);
    gl.vertexAttribPointer(radiosityAttr, 3, gl.FLOAT, false, 0, 0);
    const uViewProjection = gl.getUniformLocation(prog, "viewProjection");
    gl.useProgram(prog);
    gl.uniform1f(gl.getUniformLocation(prog, "exposure"), scene.tone.scale);
    gl.uniform1f(gl.getUniformLocation(prog, "white"), scene.tone.white);
    gl.enable(gl.DEPTH_TEST);
    gl.enable(gl.CULL_FACE);
    // Every pixel is the shader's colour rounded to 8 bits, as the project's pictures are (no dithering).
    gl.disable(gl.DITHER);

    // Orbit camera around `target`, about the scene's up axis.
    const cam = scene.camera;
    const up = norm(cam.up);
    const offset0 = sub(cam.position, cam.target);
    let radius = Math.hypot(...offset0);
    const e1 = norm(sub(offset0, scale(up, dot(offset0, up))));
    const e2 = cross(up, e1);
    let azimuth = 0;
    let elevation = Math.asin(Math.max(-1, Math.min(1, dot(offset0, up) / radius)));
    let drag = null;
    canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
    canvas.addEventListener("pointerup", () => { drag = null; });
    canvas.addEventListener("pointermove", (e) => {
        if (drag) {
            azimuth -= (e.clientX - drag[0]) * 0.008;
            elevation = Math.max(-1.5, Math.min(1.5, elevation + (e.clientY - drag[1]) * 0.008));
            drag = [e.clientX, e.clientY];
        }
    });
    canvas.addEventListener("wheel", (e) => {
        e.preventDefault();
        radius *= Math.exp(e.deltaY * 0.001);
    }, { passive: false });

    // Plot of error and unshot power against work since the last change.
    const plot = { points: [], unshotAtChange: 0 };
    const drawPlot = () => {
        const c = $("plot");
        const ctx = c.getContext("2d");
        ctx.clearRect(0, 0, c.width, c.height);
        const pts = plot.points;
        if (pts.length === 0) {
            return;
        }
        const maxWork = Math.max(1, pts[pts.length - 1].work);
        const lo = -7;
        const hi = 0;
        const x = (work) => 30 + ((c.width - 36) * work) / maxWork;
        const y = (v) => 6 + ((c.height - 24) * (hi - Math.max(lo, Math.min(hi, Math.log10(v))))) / (hi - lo);
        ctx.fillStyle = "#888";
        ctx.font = "10px sans-serif";
        for (let e = lo; e <= hi; e += 1) {
            ctx.fillText(`1e${e}`, 0, y(10 ** e) + 3);
        }
        ctx.fillText(`${maxWork} units`, c.width - 70, c.height - 4);
        const line = (key, colour) => {
            ctx.strokeStyle = colour;
            ctx.beginPath();
            let started = false;
            for (const p of pts) {
                if (p[key] === undefined || !(p[key] > 0)) {
                    continue;
                }
                if (started) {
                    ctx.lineTo(x(p.work), y(p[key]));
                } else {
                    ctx.moveTo(x(p.work), y(p[key]));
                    started = true;
                }
            }
            ctx.stroke();
        };
        line("unshot", "#777");
        line("error", "#4da3ff");
    };

    let showingTransfer = false;
    let transferAnswer = new Float32Array(3 * n);
    let radiosityAt = w.rft_radiosity();
    $("transfer").disabled = w.rft_has_transfer() === 0;
    $("transfer").addEventListener("click", () => {
        const units = w.rft_relight_transfer();
        if (units < 0) {
            fail(message());
            return;
        }
        // The wrapper wrote the answer into its radiosity buffer, whose offset does not change after loading.
        transferAnswer = new Float32Array(w.memory.buffer, radiosityAt, 3 * n).slice();
        showingTransfer = true;
        viewer.transferUnits = units;
    });

    let radiosity = new Float32Array(0);
    const readRadiosity = () => {
        radiosityAt = w.rft_radiosity();
        return new Float32Array(w.memory.buffer, radiosityAt, 3 * n).slice();
    };
    viewer.radiosity = () => Array.from(radiosity);
    viewer.intensity = (g) => intensityOf(g);
    viewer.reflectance = (m) => reflectance[m].slice();
    viewer.setLight = (g, s) => {
        lightSliders[g].value = String(s);
        lightSliders[g].dispatchEvent(new Event("input"));
    };

    const frame = () => {
        try {
            let lightUnits = 0;
            let changed = false;
            for (const g of pendingLights) {
                const units = w.rft_set_light(g, ...intensityOf(g));
                if (units < 0) {
                    throw new Error(message());
                }
                lightUnits += units;
                changed = true;
            }
            for (const m of pendingMaterials) {
                const units = w.rft_set_reflectance(m, ...reflectance[m]);
                if (units < 0) {
                    throw new Error(message());
                }
                lightUnits += units;
                changed = true;
            }
            pendingLights.clear();
            pendingMaterials.clear();
            if (changed) {
                updateExact();
                showingTransfer = false;
                plot.points = [];
                plot.unshotAtChange = 0;
                viewer.stats.workSinceChange = 0;
            }
            let used = 0;
            if (!showingTransfer) {
                used = w.rft_step(viewer.budget);
                radiosity = readRadiosity();
            } else {
                radiosity = transferAnswer;
            }
            const s = viewer.stats;
            s.frames += 1;
            s.maxUsed = Math.max(s.maxUsed, used);
            if (used > viewer.budget) {
                s.overBudget += 1;
            }
            s.workSinceChange += used + lightUnits;
            // 0 converged, 1 budget spent, 2 no progress (the transfer answer shown: no step, so "converged").
            const outcome = showingTransfer ? 0 : w.rft_outcome();
            viewer.frames.push({ budget: viewer.budget, used, lightUnits, outcome });
            if (viewer.frames.length > KEEP_FRAMES) {
                viewer.frames.shift();
            }
            viewer.converged = outcome === 0;
            const unshot = w.rft_unshot();
            if (plot.unshotAtChange === 0) {
                plot.unshotAtChange = unshot;
            }
            const error = reflectanceIsTable() ? relativeError(radiosity) : undefined;
            viewer.error_vs_exact = error;
            const last = plot.points[plot.points.length - 1];
            if (!last || last.work !== s.workSinceChange) {
                plot.points.push({
                    work: s.workSinceChange,
                    error,
                    unshot: plot.unshotAtChange > 0 ? unshot / plot.unshotAtChange : undefined,
                });
            }

            for (let v = 0; v < mesh.patchOf.length; v++) {
                const i = mesh.patchOf[v];
                vertexRadiosity[3 * v] = radiosity[3 * i];
                vertexRadiosity[3 * v + 1] = radiosity[3 * i + 1];
                vertexRadiosity[3 * v + 2] = radiosity[3 * i + 2];
            }
            const width = canvas.clientWidth;
            const height = canvas.clientHeight;
            if (canvas.width !== width || canvas.height !== height) {
                canvas.width = width;
                canvas.height = height;
            }
            gl.viewport(0, 0, canvas.width, canvas.height);
            gl.clearColor(0, 0, 0, 1);
            gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
            gl.bindBuffer(gl.ARRAY_BUFFER, radiosityBuffer);
            gl.bufferSubData(gl.ARRAY_BUFFER, 0, vertexRadiosity);
            const dir = add(scale(add(scale(e1, Math.cos(azimuth)), scale(e2, Math.sin(azimuth))),
                Math.cos(elevation)), scale(up, Math.sin(elevation)));
            const eye = add(cam.target, scale(dir, radius));
            const view = lookAt(eye, cam.target, up);
            const proj = perspective(cam.vertical_fov_deg, canvas.width / canvas.height, radius * 0.01,
                radius * 20);
            gl.uniformMatrix4fv(uViewProjection, false, multiply(proj, view));
            gl.drawArrays(gl.TRIANGLES, 0, mesh.patchOf.length);

            drawPlot();
            $("status").textContent =
                `${n} patches, ${groups} light groups, ${materials} materials\n` +
                `frame ${s.frames}: ${used} of ${viewer.budget} units` +
                (lightUnits > 0 ? ` (+${lightUnits} for the change)` : "") +
                `, ${viewer.converged ? "converged" : "shooting"}\n` +
                `work since the last change: ${s.workSinceChange} units\n` +
                (error !== undefined ? `error: ${error.toExponential(3)}`
                    : reflectanceIsTable() ? "error: n/a (the exact answer is black)"
                        : "error: n/a (reflectances changed)") +
                (showingTransfer ? `\nshowing the transfer-basis answer (${viewer.transferUnits} units)` : "");
            viewer.ready = true;
            requestAnimationFrame(frame);
        } catch (e) {
            fail(e.message ?? e);
        }
    };
    requestAnimationFrame(frame);
}

main().catch((e) => fail(e.message ?? e));
