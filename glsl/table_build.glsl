// The device build of the pre-integrated table G (MODEL §7, "Building G on the device"),
// shared by table_build_f64.comp (float64, BUILD_F64) and table_build_f32.comp. One batch
// of jobs (one w node × several wavelengths) runs as these passes, chosen by the PASS
// specialisation constant:
//   PHASE     field = exp(i·s·h), s = 2πw/λ, h mean-centred (µm)
//   FFT       one Stockham stage of radix R of the +i DFT along rows or gathered columns
//   GATHER    the row-transformed columns the lookups reach, stored contiguously
//   TAPS      the Gaussian window's weights at every lookup (u nodes, then v nodes)
//   WINDOW_X  the x pass of the separable window, for every needed row and u node
//   WINDOW_Y  the y pass at every (u, v) node, |·|²·weight summed into the slice
// The float64 path evaluates cos, sin and exp with its own range reduction and polynomials
// (GLSL has no double-precision transcendentals); the FFT twiddles come from the CPU.

layout(local_size_x = 64) in;

layout(constant_id = 0) const int PASS = 0;
layout(constant_id = 1) const int NX = 1;
layout(constant_id = 2) const int NY = 1;
layout(constant_id = 3) const int NU = 1;
layout(constant_id = 4) const int NV = 1;
// Window half-widths in texels (6σ, rounded up).
layout(constant_id = 5) const int RX = 0;
layout(constant_id = 6) const int RY = 0;
// Largest number of columns / rows any wavelength of the build reads.
layout(constant_id = 7) const int CMAX = 1;
layout(constant_id = 8) const int RMAX = 1;

const int PASS_PHASE = 0;
const int PASS_FFT = 1;
const int PASS_GATHER = 2;
const int PASS_TAPS = 3;
const int PASS_WINDOW_X = 4;
const int PASS_WINDOW_Y = 5;

const int TAPS_X = 2 * RX + 1;
const int TAPS_Y = 2 * RY + 1;
const int TAPS_PER_JOB = NU * TAPS_X + NV * TAPS_Y;

#ifdef BUILD_F64
#define REAL double
#define CPLX dvec2
#else
#define REAL float
#define CPLX vec2
#endif

layout(push_constant) uniform Push {
    // Invocations that have work (the dispatch is rounded up).
    uint total;
    // FFT: transform length, length of the sub-transforms done so far, this stage's radix.
    int n;
    int ns;
    int radix;
    // FFT: transforms per job (NY rows, or CMAX gathered columns); 0 rows, 1 columns.
    int lines;
    int axis;
    // Which field buffer is read: 0 A (writes go to B), 1 B (writes go to A).
    int src;
    int jobs;
    // The batch's first job in jobReal and first wavelength in jobInt, qx, qy.
    int jobBase;
    int lamBase;
    // Elements per job in the field buffers.
    int slot;
} pc;

layout(std430, set = 0, binding = 0) readonly buffer Heights { REAL heights[]; };
layout(std430, set = 0, binding = 1) buffer FieldA { CPLX fieldA[]; };
layout(std430, set = 0, binding = 2) buffer FieldB { CPLX fieldB[]; };
// exp(+2πi t/NX) and exp(+2πi t/NY).
layout(std430, set = 0, binding = 3) readonly buffer TwiddleX { CPLX twx[]; };
layout(std430, set = 0, binding = 4) readonly buffer TwiddleY { CPLX twy[]; };
// Per job: s, then the wavelength's X, Y, Z weight.
layout(std430, set = 0, binding = 5) readonly buffer JobReal { REAL jobReal[]; };
// Per wavelength: first column, columns, first row, rows (shifted texel indices).
layout(std430, set = 0, binding = 6) readonly buffer JobInt { int jobInt[]; };
// Per wavelength: the lookup positions of the u nodes, of the v nodes.
layout(std430, set = 0, binding = 7) readonly buffer LookupX { REAL qx[]; };
layout(std430, set = 0, binding = 8) readonly buffer LookupY { REAL qy[]; };
layout(std430, set = 0, binding = 9) buffer Taps { REAL taps[]; };
layout(std430, set = 0, binding = 10) buffer XPass { CPLX xpass[]; };
// The slice being built: XYZ per node, (i·NV + j)·3 for u node i, v node j.
layout(std430, set = 0, binding = 11) buffer Acc { REAL acc[]; };
// σ of the window along x and y (texels), 1/(NX·NY).
layout(std430, set = 0, binding = 12) readonly buffer Consts { REAL consts[]; };

#ifdef BUILD_F64
// fdlibm's kernels of sin and cos on [−π/4, π/4] (error below 1 ulp there).
double kernelSin(double x) {
    double z = x * x;
    double r = 8.33333333332248946124e-03LF +
               z * (-1.98412698298579493134e-04LF +
                    z * (2.75573137070700676789e-06LF +
                         z * (-2.50507602534068634195e-08LF + z * 1.58969099521155010221e-10LF)));
    return x + x * z * (-1.66666666666666324348e-01LF + z * r);
}

double kernelCos(double x) {
    double z = x * x;
    double r = z * (4.16666666666666019037e-02LF +
                    z * (-1.38888888888741095749e-03LF +
                         z * (2.48015872894767294178e-05LF +
                              z * (-2.75573143513906633035e-07LF +
                                   z * (2.08757232129817482790e-09LF +
                                        z * -1.13596475577881948265e-11LF)))));
    return 1.0LF - 0.5LF * z + z * r;
}

// (cos x, sin x): x = n·π/2 + r with π/2 in two parts (the first has 33 bits, so n·part is
// exact for |n| < 2^20), then the kernels by quadrant.
dvec2 cisR(double x) {
    double n = roundEven(x * 6.36619772367581382433e-01LF);
    double r = (x - n * 1.57079632673412561417e+00LF) - n * 6.07710050650619224932e-11LF;
    double s = kernelSin(r);
    double c = kernelCos(r);
    int q = int(n) & 3;
    if (q == 0) return dvec2(c, s);
    if (q == 1) return dvec2(-s, c);
    if (q == 2) return dvec2(-c, -s);
    return dvec2(s, -c);
}

// exp(x) for x ≤ 0: x = n·ln2 + r (ln2 in two parts, fdlibm's), Taylor to degree 13 on
// |r| ≤ ln2/2 (truncation below 2e-16), scaled by 2^n.
double expR(double x) {
    if (x < -708.0LF) {
        return 0.0LF;
    }
    double n = roundEven(x * 1.44269504088896338700e+00LF);
    double r = (x - n * 6.93147180369123816490e-01LF) - n * 1.90821492927058770002e-10LF;
    double p = 1.0LF;
    for (int k = 13; k >= 1; k--) {
        p = 1.0LF + p * r / double(k);
    }
    return ldexp(p, int(n));
}
#else
// Cephes' float kernels on [−π/4, π/4] after a two-part reduction by π/2.
vec2 cisR(float x) {
    float n = roundEven(x * 0.636619772f);
    float r = (x - n * 1.57079637050628662109375f) + n * 4.37113900018624283e-8f;
    float z = r * r;
    float s = ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * r + r;
    float c = ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) *
                  z * z - 0.5f * z + 1.0f;
    int q = int(n) & 3;
    if (q == 0) return vec2(c, s);
    if (q == 1) return vec2(-s, c);
    if (q == 2) return vec2(-c, -s);
    return vec2(s, -c);
}

float expR(float x) {
    return exp(x);
}
#endif

CPLX cmul(CPLX a, CPLX b) {
    return CPLX(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

CPLX loadField(int which, uint i) {
    return which == 0 ? fieldA[i] : fieldB[i];
}

void storeField(int which, uint i, CPLX z) {
    if (which == 0) {
        fieldA[i] = z;
    } else {
        fieldB[i] = z;
    }
}

// The DFT bin of shifted texel t (zero frequency at floor(n/2)); the spectrum is periodic.
// Vulkan leaves % undefined for a negative operand (it compiles to OpSMod), so a texel left
// of the zero frequency is reduced through its mirror image, with both operands ≥ 0.
int binOf(int t, int n) {
    int d = t - n / 2;
    return d >= 0 ? d % n : n - 1 - (-d - 1) % n;
}

REAL gauss(REAL d, REAL sigma) {
    return expR(-d * d / (REAL(2) * sigma * sigma));
}

void phasePass(uint id) {
    uint size = uint(NX * NY);
    uint b = id / size;
    uint e = id % size;
    REAL s = jobReal[(uint(pc.jobBase) + b) * 4u];
    fieldA[b * uint(pc.slot) + e] = cisR(s * heights[e]);
}

// One Stockham stage (decimation in time): after it, element q·L + a (L = ns·radix) of a
// line holds the length-L DFT of the line's samples q + t·(n/L), t < L.
void fftPass(uint id) {
    int o = int(id % uint(pc.n));
    uint t = id / uint(pc.n);
    int line = int(t % uint(pc.lines));
    int b = int(t / uint(pc.lines));
    if (pc.axis == 1 && line >= jobInt[(pc.lamBase + b) * 4 + 1]) {
        return;
    }
    int len = pc.ns * pc.radix;
    int a = o % len;
    int j = (o / len) * pc.ns + a % pc.ns;
    int stride = pc.n / pc.radix;
    int step = pc.n / len;
    uint base = uint(b) * uint(pc.slot) + uint(line) * uint(pc.n);
    CPLX sum = CPLX(0);
    for (int m = 0; m < pc.radix; m++) {
        CPLX x = loadField(pc.src, base + uint(j + m * stride));
        int k = ((m * a) % len) * step;
        CPLX w = pc.axis == 0 ? twx[k] : twy[k];
        sum += cmul(x, w);
    }
    storeField(1 - pc.src, base + uint(o), sum);
}

void gatherPass(uint id) {
    int r = int(id % uint(NY));
    uint t = id / uint(NY);
    int c = int(t % uint(CMAX));
    int b = int(t / uint(CMAX));
    int lam = pc.lamBase + b;
    if (c >= jobInt[lam * 4 + 1]) {
        return;
    }
    uint base = uint(b) * uint(pc.slot);
    CPLX z = loadField(pc.src, base + uint(r * NX + binOf(jobInt[lam * 4] + c, NX)));
    storeField(1 - pc.src, base + uint(c * NY + r), z);
}

void tapsPass(uint id) {
    int b = int(id / uint(NU + NV));
    int node = int(id % uint(NU + NV));
    uint base = uint(b * TAPS_PER_JOB);
    int lam = pc.lamBase + b;
    if (node < NU) {
        REAL q = qx[lam * NU + node];
        REAL a = floor(q);
        for (int d = -RX; d <= RX; d++) {
            taps[base + uint(node * TAPS_X + d + RX)] = gauss(a + REAL(d) - q, consts[0]);
        }
    } else {
        int j = node - NU;
        REAL q = qy[lam * NV + j];
        REAL a = floor(q);
        for (int d = -RY; d <= RY; d++) {
            taps[base + uint(NU * TAPS_X + j * TAPS_Y + d + RY)] = gauss(a + REAL(d) - q, consts[1]);
        }
    }
}

// Consecutive invocations take consecutive rows, so their reads of the gathered columns
// are contiguous; the result is stored per (job, u node) along the rows.
void windowXPass(uint id) {
    int rho = int(id % uint(RMAX));
    uint t = id / uint(RMAX);
    int i = int(t % uint(NU));
    int b = int(t / uint(NU));
    int lam = pc.lamBase + b;
    int cx0 = jobInt[lam * 4];
    int cy0 = jobInt[lam * 4 + 2];
    if (rho >= jobInt[lam * 4 + 3]) {
        return;
    }
    int a = int(floor(qx[lam * NU + i]));
    int fy = binOf(cy0 + rho, NY);
    uint base = uint(b) * uint(pc.slot);
    uint tapBase = uint(b * TAPS_PER_JOB + i * TAPS_X + RX);
    CPLX sum = CPLX(0);
    for (int d = -RX; d <= RX; d++) {
        CPLX z = loadField(pc.src, base + uint((a + d - cx0) * NY + fy));
        sum += z * taps[tapBase + uint(d)];
    }
    xpass[uint(b * NU + i) * uint(RMAX) + uint(rho)] = sum;
}

// Consecutive invocations take consecutive v nodes (contiguous reads of the x pass); the
// slice is stored u-major, (i·NV + j)·3, and reordered on the host.
void windowYPass(uint id) {
    int j = int(id % uint(NV));
    int i = int(id / uint(NV));
    REAL norm = consts[2];
    REAL x = acc[3u * id];
    REAL y = acc[3u * id + 1u];
    REAL z = acc[3u * id + 2u];
    for (int b = 0; b < pc.jobs; b++) {
        int lam = pc.lamBase + b;
        int cy0 = jobInt[lam * 4 + 2];
        int a = int(floor(qy[lam * NV + j]));
        uint tapBase = uint(b * TAPS_PER_JOB + NU * TAPS_X + j * TAPS_Y + RY);
        CPLX p = CPLX(0);
        for (int d = -RY; d <= RY; d++) {
            p += xpass[uint(b * NU + i) * uint(RMAX) + uint(a + d - cy0)] * taps[tapBase + uint(d)];
        }
        p *= norm;
        REAL power = p.x * p.x + p.y * p.y;
        uint jr = uint(pc.jobBase + b) * 4u;
        x += power * jobReal[jr + 1u];
        y += power * jobReal[jr + 2u];
        z += power * jobReal[jr + 3u];
    }
    acc[3u * id] = x;
    acc[3u * id + 1u] = y;
    acc[3u * id + 2u] = z;
}

void main() {
    uint id = (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * gl_WorkGroupSize.x +
              gl_LocalInvocationID.x;
    if (id >= pc.total) {
        return;
    }
    if (PASS == PASS_PHASE) {
        phasePass(id);
    } else if (PASS == PASS_FFT) {
        fftPass(id);
    } else if (PASS == PASS_GATHER) {
        gatherPass(id);
    } else if (PASS == PASS_TAPS) {
        tapsPass(id);
    } else if (PASS == PASS_WINDOW_X) {
        windowXPass(id);
    } else {
        windowYPass(id);
    }
}
