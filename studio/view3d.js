// terrainnet studio's 3D view: the terrain as a WebGL mesh draped with its hillshade, orbited with
// the mouse (drag: turn and tilt; wheel: zoom). Plain WebGL 1, no library.
'use strict';

function View3D(canvas) {
    const gl = canvas.getContext('webgl', { antialias: true, preserveDrawingBuffer: true });
    this.gl = gl;
    this.canvas = canvas;
    this.azimuth = 0.7;  // radians around the vertical
    this.pitch = 0.6;    // radians above the horizon
    this.distance = 1.8; // in map widths
    this.relief = 0.25;  // height of the full range, in map widths
    this.count = 0;
    if (!gl) return;
    const vs = 'attribute vec3 p; attribute vec3 n; attribute vec2 uv; uniform mat4 mvp; uniform float relief;' +
        'varying vec2 v_uv; varying vec3 v_n;' +
        'void main() { v_uv = uv; v_n = normalize(vec3(n.x, n.y / max(relief, 1e-3), n.z));' +
        ' gl_Position = mvp * vec4(p.x, p.y * relief, p.z, 1.0); }';
    const fs = 'precision mediump float; uniform sampler2D tex; varying vec2 v_uv; varying vec3 v_n;' +
        'void main() { vec3 c = texture2D(tex, v_uv).rgb; float l = 0.55 + 0.45 * max(dot(normalize(v_n), normalize(vec3(-0.4, 0.8, -0.3))), 0.0);' +
        ' gl_FragColor = vec4(c * l, 1.0); }';
    const compile = (type, src) => {
        const s = gl.createShader(type);
        gl.shaderSource(s, src);
        gl.compileShader(s);
        if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
        return s;
    };
    const prog = gl.createProgram();
    gl.attachShader(prog, compile(gl.VERTEX_SHADER, vs));
    gl.attachShader(prog, compile(gl.FRAGMENT_SHADER, fs));
    gl.linkProgram(prog);
    this.prog = prog;
    this.loc = {
        p: gl.getAttribLocation(prog, 'p'), n: gl.getAttribLocation(prog, 'n'), uv: gl.getAttribLocation(prog, 'uv'),
        mvp: gl.getUniformLocation(prog, 'mvp'), relief: gl.getUniformLocation(prog, 'relief'), tex: gl.getUniformLocation(prog, 'tex'),
    };
    this.buf = gl.createBuffer();
    this.ibuf = gl.createBuffer();
    this.tex = gl.createTexture();
    this.uint32 = !!gl.getExtension('OES_element_index_uint');
    let drag = null;
    canvas.addEventListener('pointerdown', (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
    canvas.addEventListener('pointerup', () => { drag = null; });
    canvas.addEventListener('pointermove', (e) => {
        if (!drag) return;
        this.azimuth += (e.clientX - drag[0]) * 0.01;
        this.pitch = Math.min(1.5, Math.max(0.05, this.pitch + (e.clientY - drag[1]) * 0.01));
        drag = [e.clientX, e.clientY];
        this.draw();
    });
    canvas.addEventListener('wheel', (e) => {
        e.preventDefault();
        this.distance = Math.min(6, Math.max(0.6, this.distance * Math.exp(e.deltaY * 0.001)));
        this.draw();
    }, { passive: false });
}

// heights: Float32Array w * h; rgba: Uint8ClampedArray of the hillshade (the same size)
View3D.prototype.setTerrain = function (heights, w, h, rgba) {
    const gl = this.gl;
    if (!gl) return;
    let lo = Infinity, hi = -Infinity;
    for (let i = 0; i < heights.length; i++) { lo = Math.min(lo, heights[i]); hi = Math.max(hi, heights[i]); }
    const span = hi > lo ? hi - lo : 1;
    // at most 256 x 256 vertices (and 65536 with 16-bit indices)
    const step = Math.max(1, Math.ceil(Math.max(w, h) / (this.uint32 ? 512 : 255)));
    const nx = Math.floor((w - 1) / step) + 1, ny = Math.floor((h - 1) / step) + 1, side = Math.max(w, h) - 1;
    const at = (x, y) => (heights[Math.min(h - 1, y) * w + Math.min(w - 1, x)] - lo) / span;
    const v = new Float32Array(nx * ny * 8);
    for (let j = 0; j < ny; j++) {
        for (let i = 0; i < nx; i++) {
            const x = i * step, y = j * step, o = (j * nx + i) * 8;
            const dzdx = (at(x + step, y) - at(Math.max(0, x - step), y)) / (2 * step / side);
            const dzdy = (at(x, y + step) - at(x, Math.max(0, y - step))) / (2 * step / side);
            v[o] = x / side - 0.5 * (w - 1) / side; v[o + 1] = at(x, y) - 0.5; v[o + 2] = y / side - 0.5 * (h - 1) / side;
            v[o + 3] = -dzdx; v[o + 4] = 1; v[o + 5] = -dzdy;
            v[o + 6] = (x + 0.5) / w; v[o + 7] = (y + 0.5) / h;
        }
    }
    const idx = new (this.uint32 ? Uint32Array : Uint16Array)((nx - 1) * (ny - 1) * 6);
    let k = 0;
    for (let j = 0; j < ny - 1; j++) {
        for (let i = 0; i < nx - 1; i++) {
            const a = j * nx + i, b = a + 1, c = a + nx, d = c + 1;
            idx[k++] = a; idx[k++] = c; idx[k++] = b; idx[k++] = b; idx[k++] = c; idx[k++] = d;
        }
    }
    gl.bindBuffer(gl.ARRAY_BUFFER, this.buf);
    gl.bufferData(gl.ARRAY_BUFFER, v, gl.STATIC_DRAW);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.ibuf);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
    this.count = idx.length;
    gl.bindTexture(gl.TEXTURE_2D, this.tex);
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, w, h, 0, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(rgba.buffer, rgba.byteOffset, rgba.length));
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    this.draw();
};

function mat4Mul(a, b) { // column-major a * b
    const r = new Float32Array(16);
    for (let c = 0; c < 4; c++) for (let rr = 0; rr < 4; rr++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += a[k * 4 + rr] * b[c * 4 + k];
        r[c * 4 + rr] = s;
    }
    return r;
}

View3D.prototype.draw = function () {
    const gl = this.gl;
    if (!gl) return;
    const W = this.canvas.width, H = this.canvas.height;
    gl.viewport(0, 0, W, H);
    gl.clearColor(0.80, 0.87, 0.94, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    if (!this.count) return;
    gl.enable(gl.DEPTH_TEST);
    // camera on a sphere around the centre, looking at it
    const ce = Math.cos(this.pitch), eye = [this.distance * ce * Math.sin(this.azimuth), this.distance * Math.sin(this.pitch),
        this.distance * ce * Math.cos(this.azimuth)];
    const f = eye.map((x) => -x), fl = Math.hypot(f[0], f[1], f[2]);
    for (let i = 0; i < 3; i++) f[i] /= fl;
    let s = [f[1] * 0 - f[2] * 1, f[2] * 0 - f[0] * 0, f[0] * 1 - f[1] * 0];
    const sl = Math.hypot(s[0], s[1], s[2]);
    s = s.map((x) => x / sl);
    const u = [s[1] * f[2] - s[2] * f[1], s[2] * f[0] - s[0] * f[2], s[0] * f[1] - s[1] * f[0]];
    const view = new Float32Array([s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
        -(s[0] * eye[0] + s[1] * eye[1] + s[2] * eye[2]), -(u[0] * eye[0] + u[1] * eye[1] + u[2] * eye[2]),
        f[0] * eye[0] + f[1] * eye[1] + f[2] * eye[2], 1]);
    const near = 0.05, far = 20, t = 1 / Math.tan(0.5 * 0.75), aspect = W / H;
    const proj = new Float32Array([t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0]);
    gl.useProgram(this.prog);
    gl.uniformMatrix4fv(this.loc.mvp, false, mat4Mul(proj, view));
    gl.uniform1f(this.loc.relief, this.relief);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.tex);
    gl.uniform1i(this.loc.tex, 0);
    gl.bindBuffer(gl.ARRAY_BUFFER, this.buf);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, this.ibuf);
    gl.enableVertexAttribArray(this.loc.p);
    gl.vertexAttribPointer(this.loc.p, 3, gl.FLOAT, false, 32, 0);
    gl.enableVertexAttribArray(this.loc.n);
    gl.vertexAttribPointer(this.loc.n, 3, gl.FLOAT, false, 32, 12);
    gl.enableVertexAttribArray(this.loc.uv);
    gl.vertexAttribPointer(this.loc.uv, 2, gl.FLOAT, false, 32, 24);
    gl.drawElements(gl.TRIANGLES, this.count, this.uint32 ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT, 0);
};
