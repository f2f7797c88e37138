/*
 * mpc_native.c -- the mpc_actuator model as a native FMI 2.0 FMU (co-simulation), no Python needed.
 *
 * Built by `python build_fmu.py --native` (fmu_shim/native/package.py) together with the generated header
 * mpc_native_gen.h (fmu_shim/native/codegen.py), which holds every equation of the model, traced with SymPy
 * from the functions of fmu_src (rates, force, contact force, sensor readings, stability step, tolerance
 * scales, the loop field of Eq. 2), every constant (layout of the integrator's arrays, DP5 tableau, dense
 * output, Gauss-Legendre nodes) and the FMU's parameter metadata. This file holds no equation of the model:
 *
 *   - the force kernel's table, computed at initialisation like fmu_src.field.ForceKernel: 64-point
 *     Gauss-Legendre quadrature of the generated field functions (field.force_kernel) on 1201 points, then
 *     scipy's not-a-knot CubicSpline (its tridiagonal system, as LAPACK gtsv solves it without pivoting);
 *   - the integrator, fmu_src/integrator.py step for step on the same arrays S and W (same layout, same
 *     names): DP5(4), error norm, step control, dense output, contact/release events located on the dense
 *     output by bisection + secant;
 *   - the FMI 2.0 layer, mirroring the pythonfmu slave fmu_src/mpc_actuator.py (checks, error messages,
 *     communication-point rules, FMU state).
 *
 * Recoverable errors (invalid parameters, a failed step) are logged and return fmi2Error; the instance can be
 * reset or freed. Build: cc -std=c99 -O2 -shared -fPIC -fvisibility=hidden -ffp-contract=off
 *   -o mpc_actuator_native.so mpc_native.c -lm
 */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mpc_native_gen.h"
#include "mpc_native_vars.h"

/* ---- FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h) ---- */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
#define fmi2True 1
#define fmi2False 0
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;
typedef struct {
    fmi2Boolean newDiscreteStatesNeeded, terminateSimulation, nominalsOfContinuousStatesChanged,
        valuesOfContinuousStatesChanged, nextEventTimeDefined;
    fmi2Real nextEventTime;
} fmi2EventInfo;

#ifndef EXPORT /* mpc_native_fmi3.c defines it as static: there the FMI 2.0 functions are internal */
#if defined(_WIN32)
#define EXPORT __declspec(dllexport)
#else
#define EXPORT __attribute__((visibility("default")))
#endif
#endif

#define NSEG (N_KERNEL_POINTS - 1)
#define ME_EVENT_TOL 1e-9 /* model exchange: an impact within this fraction of max(r0, 1 mm) of the face counts */
#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ------------------------------------------------------------------------------------------ model */
/* Everything that determines the model's future (the FMU state is a copy of it: no pointers inside). */
typedef struct {
    double par[N_PARAMS]; /* parameter values in fmu_src.specs.BLOCK order */
    int blocked;
    double rtol;
    double V;             /* the input */
    int initialized;      /* fmi2ExitInitializationMode reached (fixed parameters frozen) */
    int model_ok;         /* a model exists (ExitInitializationMode succeeded) */
    double t0, stop_time, t_limit;
    int has_stop;
    double t;             /* view time (Integrator.t) */
    int mask;
    double S[NS];
    double W[NW * NMAX];  /* row r, state i: W[r*NMAX + i] */
    double coef[4 * NSEG];
    double out[8];
    int out_valid;
} Model;

typedef struct {
    Model m;
    fmi2CallbackFunctions cb;
    char name[256];
    int logging;
    int me; /* instantiated for model exchange */
} Instance;

#define ROW(W, r) ((W) + (r) * NMAX)

static const Physics *physics(const Model *m) { return &PHYSICS[m->mask]; }

/* ---- force kernel (fmu_src.field) ---- */
static double force_kernel(double r, double a, double D, double kB) {
    /* field.force_kernel: -0.5*tm * sum_k w_k b(th_k) db/dr(th_k), th_k = 0.5*tm*(node_k + 1) */
    double tm = THETA_MAX(r, D), acc = 0.0;
    for (int k = 0; k < N_GL; k++) {
        double th = 0.5 * tm * (GL_NODES[k] + 1.0);
        acc += FIELD_PER_AMP(r, th, a, kB) * DFIELD_DR_PER_AMP(r, th, a, kB) * GL_WEIGHTS[k];
    }
    return -0.5 * tm * acc;
}

/* ForceKernel(a, D, kB, r_max): scipy CubicSpline (not-a-knot) of force_kernel on linspace(0, r_max, n). */
static int make_kernel_table(Model *m) {
    const double a = m->par[PI_a], D = m->par[PI_D], kB = m->par[PI_kB];
    const double r_max = KERNEL_R_MAX(m->par[PI_r0]);
    const int n = N_KERNEL_POINTS;
    double *buf = (double *)malloc(8 * N_KERNEL_POINTS * sizeof(double));
    if (!buf) return 0;
    double *x = buf, *y = x + n, *dx = y + n, *slope = dx + n, *dl = slope + n, *dd = dl + n, *du = dd + n, *b = du + n;
    const double step = r_max / (double)(n - 1);
    for (int i = 0; i < n; i++) x[i] = (double)i * step + 0.0;
    x[n - 1] = r_max;
    for (int i = 0; i < n; i++) y[i] = force_kernel(x[i], a, D, kB);
    for (int i = 0; i < n - 1; i++) {
        dx[i] = x[i + 1] - x[i];
        slope[i] = (y[i + 1] - y[i]) / dx[i];
    }
    /* the tridiagonal system of the slopes s: row i has dl[i]*s[i-1] + dd[i]*s[i] + du[i]*s[i+1] = b[i] */
    for (int i = 1; i < n - 1; i++) {
        dd[i] = 2 * (dx[i - 1] + dx[i]);
        du[i] = dx[i - 1];
        dl[i] = dx[i];
        b[i] = 3 * (dx[i] * slope[i - 1] + dx[i - 1] * slope[i]);
    }
    {
        double d = x[2] - x[0];
        dd[0] = dx[1];
        du[0] = d;
        b[0] = ((dx[0] + 2 * d) * dx[1] * slope[0] + dx[0] * dx[0] * slope[1]) / d;
        d = x[n - 1] - x[n - 3];
        dd[n - 1] = dx[n - 2];
        dl[n - 1] = d;
        b[n - 1] = (dx[n - 2] * dx[n - 2] * slope[n - 3] + (2 * d + dx[n - 2]) * dx[n - 3] * slope[n - 2]) / d;
    }
    /* LAPACK dgtsv without row interchanges (the system is diagonally dominant enough: gtsv interchanges only
       where |sub-diagonal| > |diagonal|); the sub-diagonal of column i is dl[i+1] */
    for (int i = 0; i < n - 1; i++) {
        if (fabs(dl[i + 1]) > fabs(dd[i])) { /* would need pivoting: not this table */
            free(buf);
            return 0;
        }
        double fact = dl[i + 1] / dd[i];
        dd[i + 1] = dd[i + 1] - fact * du[i];
        b[i + 1] = b[i + 1] - fact * b[i];
    }
    b[n - 1] = b[n - 1] / dd[n - 1];
    b[n - 2] = (b[n - 2] - du[n - 2] * b[n - 1]) / dd[n - 2];
    for (int i = n - 3; i >= 0; i--) b[i] = (b[i] - du[i] * b[i + 1]) / dd[i];
    /* CubicHermiteSpline's coefficients: rows c3, c2, c1, c0 (highest power first), piece i */
    for (int i = 0; i < n - 1; i++) {
        double t = (b[i] + b[i + 1] - 2 * slope[i]) / dx[i];
        m->coef[0 * NSEG + i] = t / dx[i];
        m->coef[1 * NSEG + i] = (slope[i] - b[i]) / dx[i] - t;
        m->coef[2 * NSEG + i] = b[i];
        m->coef[3 * NSEG + i] = y[i];
    }
    m->S[K_DR] = x[1] - x[0];
    free(buf);
    for (int i = 0; i < 4 * NSEG; i++)
        if (!isfinite(m->coef[i])) return 0;
    m->S[K_SMAX] = (double)(n - 2);
    m->S[K_INVDR] = 1.0 / m->S[K_DR];
    m->S[K_G0] = m->coef[3 * NSEG + 0];
    m->S[K_DG0] = m->coef[2 * NSEG + 0];
    return isfinite(m->S[K_G0]) && isfinite(m->S[K_DG0]);
}

/* field.kernel_value on the table (off = 0) */
static double kernel(const double *S, const double *coef, double r) {
    double smax = S[K_SMAX];
    double s = fmax(r, 0.0) * S[K_INVDR];
    s = s < smax ? s : smax;
    long i = (long)s;
    if (i < 0) i = 0;
    if (i > (long)smax) i = (long)smax;
    double u = r - (double)i * S[K_DR];
    double g = ((coef[0 * NSEG + i] * u + coef[1 * NSEG + i]) * u + coef[2 * NSEG + i]) * u + coef[3 * NSEG + i];
    return g + (r < 0.0 ? 1.0 : 0.0) * (S[K_G0] + S[K_DG0] * r - g);
}

/* ---- integrator.py: physics wrappers ---- */
static double force_at(const Model *m, double I, double r) {
    return physics(m)->force(m->S, I, kernel(m->S, m->coef, r));
}

static void rhs(const Model *m, const double *y, double V, int mode, double *out) {
    double x, v;
    if (mode == FREE) {
        x = y[1];
        v = y[2];
    } else if (mode == CONTACT) {
        x = m->S[P_R0];
        v = 0.0;
    } else {
        x = 0.0;
        v = 0.0;
    }
    int free_ = mode == FREE;
    double F = 0.0;
    if (free_ || physics(m)->drives) F = force_at(m, y[0], m->S[P_R0] - x);
    physics(m)->rates[free_](m->S, y, V, x, v, F, out);
}

static double net_contact_force(const Model *m, const double *y) {
    return physics(m)->contact(m->S, y, force_at(m, y[0], 0.0));
}

static void outputs(const Model *m, const double *y, int mode, double *out) {
    double r = m->S[P_R0] - y[1];
    r = r > 0.0 ? r : 0.0; /* Python max(r0 - x, 0.0) */
    double F = force_at(m, y[0], r);
    out[0] = y[0];
    out[1] = y[1];
    out[2] = y[2];
    out[3] = F;
    out[4] = AXIAL_FIELD(y[0], r, m->S[P_A], m->S[P_KB]);
    out[5] = mode == CONTACT ? 1.0 : 0.0;
    physics(m)->sensor(m->S, y, y[1], F, &out[6], &out[7]);
}

/* ---- integrator.py: the integrator ---- */
static void interp(const Model *m, double t, double *out) {
    const double *S = m->S, *W = m->W;
    int n = (int)S[P_N];
    double t0 = S[S_DT0], h = S[S_DH];
    double s = (t - t0) / h, s2 = s * s, s3 = s2 * s, s4 = s3 * s;
    for (int i = 0; i < n; i++)
        out[i] = ROW(W, W_DY0)[i] + h * (ROW(W, W_DQ)[i] * s + ROW(W, W_DQ + 1)[i] * s2 + ROW(W, W_DQ + 2)[i] * s3
                                         + ROW(W, W_DQ + 3)[i] * s4);
}

static double event_g(Model *m, int kind, double s) {
    double *yc = ROW(m->W, W_YC);
    interp(m, m->S[S_DT0] + s * m->S[S_DH], yc);
    if (kind == 0) return yc[1] - m->S[P_R0];
    return -net_contact_force(m, yc);
}

static double root(Model *m, int kind) {
    const double tol = 1e-13;
    double lo = 0.0, hi = 1.0;
    double glo = event_g(m, kind, lo), ghi = event_g(m, kind, hi);
    if (glo >= 0.0) return 0.0;
    for (int it = 0; it < 80; it++) {
        double s = ghi != glo ? hi - ghi * (hi - lo) / (ghi - glo) : 0.5 * (lo + hi);
        if (!(lo < s && s < hi)) s = 0.5 * (lo + hi);
        double gs = event_g(m, kind, s);
        if (gs >= 0.0) {
            hi = s;
            ghi = gs;
        } else {
            lo = s;
            glo = gs;
        }
        if (hi - lo < tol) break;
    }
    return hi;
}

static void truncate_dense(Model *m, double s) {
    int n = (int)m->S[P_N];
    for (int i = 0; i < n; i++) {
        ROW(m->W, W_DQ + 1)[i] = ROW(m->W, W_DQ + 1)[i] * s;
        ROW(m->W, W_DQ + 2)[i] = ROW(m->W, W_DQ + 2)[i] * s * s;
        ROW(m->W, W_DQ + 3)[i] = ROW(m->W, W_DQ + 3)[i] * (s * s * s); /* numba's s ** 3, not pow */
    }
    m->S[S_DH] = s * m->S[S_DH];
}

static void stop_at_event(Model *m, int kind, double t0, double h) {
    int n = (int)m->S[P_N];
    double s = root(m, kind);
    double *yc = ROW(m->W, W_YC), *y = ROW(m->W, W_Y);
    interp(m, t0 + s * h, yc);
    yc[1] = m->S[P_R0];
    yc[2] = 0.0;
    if (s > 0) truncate_dense(m, s);
    else m->S[S_DENSE] = 0.0;
    m->S[S_TF] = t0 + s * h;
    for (int i = 0; i < n; i++) y[i] = yc[i];
    m->S[S_K0] = 0.0;
}

static double pymax(double a, double b) { return b > a ? b : a; } /* Python's max(a, b) */
static double pymin(double a, double b) { return b < a ? b : a; } /* Python's min(a, b) */

static int step(Model *m, double t_end) {
    double *S = m->S, *W = m->W;
    int n = (int)S[P_N];
    double V = S[S_V];
    int mode = (int)S[S_MODE];
    double *y = ROW(W, W_Y);
    if (S[S_K0] == 0.0) {
        rhs(m, y, V, mode, ROW(W, W_K));
        S[S_K0] = 1.0;
    }
    double *k1 = ROW(W, W_K), *k2 = ROW(W, W_K + 1), *k3 = ROW(W, W_K + 2), *k4 = ROW(W, W_K + 3);
    double *k5 = ROW(W, W_K + 4), *k6 = ROW(W, W_K + 5), *k7 = ROW(W, W_K + 6);
    double *ynew = ROW(W, W_YNEW), *tmp = ROW(W, W_TMP);
    double t = S[S_TF];
    double h = pymin(S[S_H], S[P_MAXSTEP]);
    int clipped = 0;
    if (S[S_CHANGED] != 0.0 && t + h > t_end) {
        h = t_end - t;
        clipped = 1;
    }
    double rtol = S[P_RTOL];
    for (;;) {
        for (int i = 0; i < n; i++) tmp[i] = y[i] + h * A21 * k1[i];
        rhs(m, tmp, V, mode, k2);
        for (int i = 0; i < n; i++) tmp[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        rhs(m, tmp, V, mode, k3);
        for (int i = 0; i < n; i++) tmp[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        rhs(m, tmp, V, mode, k4);
        for (int i = 0; i < n; i++) tmp[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        rhs(m, tmp, V, mode, k5);
        for (int i = 0; i < n; i++)
            tmp[i] = y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        rhs(m, tmp, V, mode, k6);
        for (int i = 0; i < n; i++)
            ynew[i] = y[i] + h * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i]);
        rhs(m, ynew, V, mode, k7);
        double err = 0.0;
        for (int i = 0; i < n; i++) {
            double e = h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            double sc = S[P_ATOL + i] + rtol * pymax(fabs(y[i]), fabs(ynew[i]));
            err += (e / sc) * (e / sc);
        }
        err = sqrt(err / n);
        if (err <= 1.0) {
            double fac = err == 0.0 ? 5.0 : pymin(5.0, pymax(0.2, 0.9 * pow(err, -0.2)));
            if (!(clipped && fac * h < S[S_H])) S[S_H] = h * fac;
            break;
        }
        if (!isfinite(err)) h *= 0.1;
        else h *= pymax(0.1, 0.9 * pow(err, -0.2));
        clipped = 0;
        if (h < H_MIN) return ST_UNDERFLOW;
    }
    /* dense record of the accepted step: Q = K^T P */
    double t0 = t;
    S[S_DENSE] = 1.0;
    S[S_DT0] = t0;
    S[S_DH] = h;
    S[S_DMODE] = mode;
    static const int JS[6] = {0, 2, 3, 4, 5, 6};
    for (int i = 0; i < n; i++) {
        ROW(W, W_DY0)[i] = y[i];
        for (int c = 0; c < 4; c++) {
            double q = 0.0;
            for (int jj = 0; jj < 6; jj++) q += ROW(W, W_K + JS[jj])[i] * DENSE_P[JS[jj] * 4 + c];
            ROW(W, W_DQ + c)[i] = q;
        }
    }
    /* events */
    double r0 = S[P_R0];
    if (mode == FREE && ynew[1] > r0) {
        stop_at_event(m, 0, t0, h); /* impact on the coil face */
        if (net_contact_force(m, y) >= 0.0) S[S_MODE] = CONTACT;
        else {
            S[S_MODE] = FREE;
            y[1] = r0 * (1.0 - 1e-12);
        }
        return ST_OK;
    }
    if (mode == CONTACT && net_contact_force(m, ynew) < 0.0) {
        stop_at_event(m, 1, t0, h); /* release */
        S[S_MODE] = FREE;
        return ST_OK;
    }
    S[S_TF] = t0 + h;
    for (int i = 0; i < n; i++) {
        y[i] = ynew[i];
        k1[i] = k7[i];
    }
    return ST_OK;
}

static void update_view(Model *m) {
    double *S = m->S, *W = m->W;
    int n = (int)S[P_N];
    double t = S[S_T];
    double *view = ROW(W, W_VIEW);
    if (S[S_DENSE] != 0.0 && S[S_DT0] <= t && t < S[S_TF]) {
        interp(m, t, view);
        if ((int)S[S_DMODE] != FREE) {
            view[1] = ROW(W, W_DY0)[1];
            view[2] = 0.0;
        } else if (view[1] > S[P_R0]) {
            view[1] = S[P_R0];
        }
        S[S_VMODE] = S[S_DMODE];
    } else {
        for (int i = 0; i < n; i++) view[i] = ROW(W, W_Y)[i];
        S[S_VMODE] = S[S_MODE];
    }
}

static int advance(Model *m, double t_end, double V) {
    double *S = m->S, *W = m->W;
    int n = (int)S[P_N];
    int changed = V != S[S_V];
    S[S_CHANGED] = changed ? 1.0 : 0.0;
    if (changed) {
        S[S_TF] = S[S_T];
        for (int i = 0; i < n; i++) ROW(W, W_Y)[i] = ROW(W, W_VIEW)[i];
        S[S_MODE] = S[S_VMODE];
        S[S_K0] = 0.0;
        S[S_DENSE] = 0.0;
        S[S_V] = V;
    }
    long n_steps = 0;
    while (S[S_TF] < t_end) {
        if (n_steps >= S[P_MAXSTEPS]) return ST_TOO_MANY_STEPS;
        int status = step(m, t_end);
        if (status != ST_OK) return status;
        n_steps++;
    }
    S[S_T] = t_end;
    update_view(m);
    return ST_OK;
}

/* ---- model.py: Dynamics / Integrator set-up and reset ---- */
static void reset_integrator(Model *m, double t0) {
    double *S = m->S;
    int n = (int)S[P_N];
    double y[NMAX] = {0};
    int mode;
    if (m->blocked) {
        mode = BLOCKED;
        y[1] = y[2] = 0.0;
    } else if (y[1] >= m->par[PI_r0]) {
        mode = CONTACT;
        y[1] = m->par[PI_r0];
        y[2] = 0.0;
    } else mode = FREE;
    m->t = t0;
    for (int i = NP; i < NS; i++) S[i] = 0.0;
    S[S_T] = S[S_TF] = t0;
    S[S_MODE] = S[S_VMODE] = mode;
    S[S_V] = NAN;
    S[S_CHANGED] = 1.0;
    S[S_H] = H_FIRST;
    memset(m->W, 0, sizeof m->W);
    for (int i = 0; i < n; i++) ROW(m->W, W_Y)[i] = ROW(m->W, W_VIEW)[i] = y[i];
}

/* the parameter block, the kernel table and the integrator's settings (Dynamics + Integrator.__init__) */
static int setup_model(Model *m) {
    double *S = m->S;
    int mask = 0;
    for (int k = 0; k < N_EFFECTS; k++)
        if (m->par[EFFECT_SWITCH[k]] != 0.0) mask |= 1 << k;
    m->mask = mask;
    memset(S, 0, sizeof m->S);
    for (int i = 0; i < N_PARAMS; i++) S[i] = m->par[i];
    for (int k = 0; k < N_EFFECTS; k++) S[EFFECT_SWITCH_SLOT[k]] = (mask >> k & 1) ? 1.0 : 0.0;
    /* effect state indices: position in y (I, x, v, then the states of the effects on), -1 when off */
    int pos = N_BASE_STATES;
    for (int j = 0; j < N_EFFECT_STATES; j++) {
        int on = mask >> STATE_EFFECT[j] & 1;
        S[STATE_SLOT[j]] = on ? (double)pos++ : -1.0;
    }
    /* the generic term set (fmu_src.terms), as fmu_src.model.block_head writes it: its switch (1.0 while any
       coefficient is nonzero: the mask's TERMS_BIT), each lag's switch (1.0 while a term with a nonzero coefficient
       uses it), the lag states after the effect states while the term set is on (-1 when off) */
    int terms = 0;
    for (int k = 0; k < N_TERMS; k++)
        if (m->par[TERM_COEF[k]] != 0.0) terms = 1;
    if (terms) m->mask = mask | TERMS_BIT;
    S[TERMS_SLOT] = terms ? 1.0 : 0.0;
    for (int g = 0; g < N_LAGS; g++) S[LAG_ON_SLOT[g]] = 0.0;
    for (int k = 0; k < N_TERMS; k++)
        if (TERM_LAG[k] >= 0 && m->par[TERM_COEF[k]] != 0.0) S[LAG_ON_SLOT[TERM_LAG[k]]] = 1.0;
    for (int j = 0; j < N_LAG_STATES; j++) S[LAG_STATE_SLOT[j]] = terms ? (double)pos++ : -1.0;
    const Physics *ph = physics(m);
    if (pos != ph->n) return 0;
    if (!make_kernel_table(m)) return 0;
    S[P_N] = ph->n;
    S[P_RTOL] = m->rtol;
    double hs = ph->stab[m->blocked ? 1 : 0](S);
    S[P_MAXSTEP] = pymin(MAX_STEP_DEFAULT, hs);
    S[P_MAXSTEPS] = MAX_STEPS_PER_ADVANCE;
    double sc[NMAX];
    ph->scales(S, sc);
    for (int i = 0; i < ph->n; i++) S[P_ATOL + i] = m->rtol * sc[i];
    return 1;
}

/* ---- logging ---- */
static void logf_(Instance *c, fmi2Status st, const char *category, const char *fmt, ...) {
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (c && c->cb.logger && (st >= fmi2Warning || c->logging))
        c->cb.logger(c->cb.componentEnvironment, c->name, st, category, "%s: %s", c->name, msg);
}
#define ERROR(c, ...) logf_((c), fmi2Error, "logStatusError", __VA_ARGS__)

/* specs.validate, the rtol checks and model.check_integrable: 0 and a message naming the parameter if refused */
static int check_parameters(Instance *c) {
    Model *m = &c->m;
    for (int i = 0; i < N_PARAMS; i++) {
        double v = m->par[i];
        if (!isfinite(v)) {
            ERROR(c, "invalid parameter: parameter %s must be finite, got %.17g", PARAM_NAMES[i], v);
            return 0;
        }
        if (PARAM_POSITIVE[i] && !(v > 0.0)) {
            ERROR(c, "invalid parameter: parameter %s [%s] must be > 0, got %.17g", PARAM_NAMES[i], PARAM_UNITS[i], v);
            return 0;
        }
        if (PARAM_NONNEGATIVE[i] && !(v >= 0.0)) {
            ERROR(c, "invalid parameter: parameter %s [%s] must be >= 0, got %.17g", PARAM_NAMES[i], PARAM_UNITS[i], v);
            return 0;
        }
    }
    for (int k = 0; k < N_RULES; k++) {
        int e = RULE_EFFECT[k], p = RULE_PARAM[k];
        if (m->par[EFFECT_SWITCH[e]] > 0.0 && !(m->par[p] > 0.0)) {
            ERROR(c, "invalid parameter: parameter %s [%s] must be > 0 when %s > 0 (%s on), got %.17g", PARAM_NAMES[p],
                  PARAM_UNITS[p], PARAM_NAMES[EFFECT_SWITCH[e]], EFFECT_NAMES[e], m->par[p]);
            return 0;
        }
    }
    /* fmu_src.terms.check_terms: a term on needs its lag's time constant > 0 */
    for (int k = 0; k < N_TERMS; k++) {
        if (TERM_LAG[k] < 0 || m->par[TERM_COEF[k]] == 0.0) continue;
        int tau = LAG_TAU[TERM_LAG[k]];
        if (!(m->par[tau] > 0.0)) {
            ERROR(c, "invalid parameter: parameter %s [s] must be > 0 when %s != 0 (term %s on), got %.17g",
                  PARAM_NAMES[tau], PARAM_NAMES[TERM_COEF[k]], TERM_NAMES[k], m->par[tau]);
            return 0;
        }
    }
    if (!(isfinite(m->rtol) && m->rtol > 0.0)) {
        ERROR(c, "invalid parameter: parameter rtol must be > 0 and finite, got %.17g", m->rtol);
        return 0;
    }
    if (!(RTOL_MIN <= m->rtol && m->rtol <= RTOL_MAX)) {
        ERROR(c, "invalid parameter: parameter rtol must be in [%g, %g], got %.17g", RTOL_MIN, RTOL_MAX, m->rtol);
        return 0;
    }
    /* check_integrable */
    const double *p = m->par;
    double r0_max = R0_MAX_PER_A * p[PI_a] - 0.01;
    if (p[PI_r0] > r0_max) {
        ERROR(c, "invalid parameter: parameter r0 [m] = %.17g is too large for the coil radius a = %.17g m: the "
                 "force-kernel table resolves gaps up to %g*a - 0.01 m = %.6g m", p[PI_r0], p[PI_a], R0_MAX_PER_A, r0_max);
        return 0;
    }
    double scales[4 + N_OWNED + N_LAGS];
    const char *what[4 + N_OWNED + N_LAGS];
    int bounded_above[4 + N_OWNED + N_LAGS], ns = 0;
    scales[ns] = p[PI_L] / p[PI_R], what[ns] = "L/R (parameters L, R)", bounded_above[ns++] = 1;
    if (!m->blocked) {
        scales[ns] = sqrt(p[PI_m] / p[PI_K2]), what[ns] = "sqrt(m/K2) (parameters m, K2)", bounded_above[ns++] = 1;
        scales[ns] = sqrt(p[PI_m] / (3 * p[PI_K1] * p[PI_r0] * p[PI_r0] + p[PI_K2]));
        what[ns] = "sqrt(m/(3*K1*r0^2 + K2)) (parameters m, K1, r0, K2)", bounded_above[ns++] = 0;
        if (p[PI_C] > 0.0) scales[ns] = p[PI_m] / p[PI_C], what[ns] = "m/C (parameters m, C)", bounded_above[ns++] = 0;
    }
    for (int k = 0; k < N_OWNED; k++)
        if (p[EFFECT_SWITCH[OWNER_EFFECT[k]]] != 0.0 && PARAM_IS_TIME[OWNER_PARAM[k]])
            scales[ns] = p[OWNER_PARAM[k]], what[ns] = PARAM_NAMES[OWNER_PARAM[k]], bounded_above[ns++] = 1;
    for (int g = 0; g < N_LAGS; g++) { /* the time constants of the lags in use (terms.lags_in_use) */
        int used = 0;
        for (int k = 0; k < N_TERMS; k++)
            if (TERM_LAG[k] == g && p[TERM_COEF[k]] != 0.0) used = 1;
        if (used) scales[ns] = p[LAG_TAU[g]], what[ns] = PARAM_NAMES[LAG_TAU[g]], bounded_above[ns++] = 1;
    }
    for (int i = 0; i < ns; i++)
        if (!(scales[i] >= MIN_TIME_SCALE_S)) {
            ERROR(c, "invalid parameter: time scale %s = %.3g s below %g s: physically absurd parameters (the "
                     "integrator's smallest step is %g s)", what[i], scales[i], MIN_TIME_SCALE_S, H_MIN);
            return 0;
        }
    for (int i = 0; i < ns; i++)
        if (bounded_above[i] && !(scales[i] <= MAX_TIME_SCALE_S)) {
            ERROR(c, "invalid parameter: time scale %s = %.3g s above %g s (about a day): physically absurd "
                     "parameters (a unit slip?)", what[i], scales[i], MAX_TIME_SCALE_S);
            return 0;
        }
    double g0 = force_kernel(0.0, p[PI_a], p[PI_D], 1.0);
    double area = M_PI * p[PI_D] * p[PI_D] / 4.0;
    double ratio = p[PI_Em] * g0 / (area / (2.0 * MU0));
    if (!(ratio <= MAX_FACE_TRACTION)) {
        ERROR(c, "invalid parameter: parameters Em = %.6g N.m/T2, a = %.6g m, D = %.6g m: the magnetic force at the "
                 "coil face is %.3g times the most a 1 T field can pull on the diaphragm's area: physically absurd "
                 "parameters", p[PI_Em], p[PI_a], p[PI_D], ratio);
        return 0;
    }
    return 1;
}

/* ---- model exchange: the state vector z = I, x, v, every effect state (BLOCK.state order; 0 while its
   effect is off) and every lag state of the term set (BLOCK.lag_state order; 0 while every term is off), the
   integrator's view row W_VIEW and mode S_VMODE as the current state; N_ME_STATES of them ---- */
#define N_ME_STATES (N_BASE_STATES + N_EFFECT_STATES + N_LAG_STATES)
/* the position in y of the j-th extra state of z (effect states, then lag states), -1 if not in y */
static int me_pos(const Model *m, int j) {
    return (int)m->S[j < N_EFFECT_STATES ? STATE_SLOT[j] : LAG_STATE_SLOT[j - N_EFFECT_STATES]];
}
static void me_get_z(const Model *m, double *z) {
    memset(z, 0, N_ME_STATES * sizeof(double));
    if (!m->model_ok) return;
    const double *y = ROW(m->W, W_VIEW);
    for (int i = 0; i < N_BASE_STATES; i++) z[i] = y[i];
    for (int j = 0; j < N_EFFECT_STATES + N_LAG_STATES; j++) {
        int pos = me_pos(m, j);
        if (pos >= 0) z[N_BASE_STATES + j] = y[pos];
    }
}

static void me_set_z(Model *m, const double *z) {
    double *y = ROW(m->W, W_VIEW);
    for (int i = 0; i < N_BASE_STATES; i++) y[i] = z[i];
    for (int j = 0; j < N_EFFECT_STATES + N_LAG_STATES; j++) {
        int pos = me_pos(m, j);
        if (pos >= 0) y[pos] = z[N_BASE_STATES + j];
    }
    m->out_valid = 0;
}

static void me_derivatives(const Model *m, double *dz) {
    memset(dz, 0, N_ME_STATES * sizeof(double));
    if (!m->model_ok) return;
    double dy[NMAX];
    rhs(m, ROW(m->W, W_VIEW), m->V, (int)m->S[S_VMODE], dy);
    for (int i = 0; i < N_BASE_STATES; i++) dz[i] = dy[i];
    for (int j = 0; j < N_EFFECT_STATES + N_LAG_STATES; j++) {
        int pos = me_pos(m, j);
        if (pos >= 0) dz[N_BASE_STATES + j] = dy[pos];
    }
}

/* the event indicator: free r0 - x (impact when it reaches 0), contact the net contact force (release when it
   turns negative), blocked 1 */
static double me_indicator(const Model *m) {
    const double *y = ROW(m->W, W_VIEW);
    int mode = (int)m->S[S_VMODE];
    if (mode == FREE) return m->S[P_R0] - y[1];
    if (mode == CONTACT) return net_contact_force(m, y);
    return 1.0;
}

/* the discrete part of integrator.py's events at the current state: impact (perfectly inelastic, contact if the
   net force holds the diaphragm, else just off the face as _step does) and release; 1 if the state changed */
static int me_events(Model *m) {
    double *y = ROW(m->W, W_VIEW), r0 = m->S[P_R0];
    int mode = (int)m->S[S_VMODE];
    double tol = ME_EVENT_TOL * (r0 > 1e-3 ? r0 : 1e-3);
    if (mode == FREE && y[1] >= r0 - tol && y[2] >= 0.0) {
        y[1] = r0;
        y[2] = 0.0;
        if (net_contact_force(m, y) >= 0.0) m->S[S_VMODE] = CONTACT;
        else y[1] = r0 * (1.0 - 1e-12);
        m->out_valid = 0;
        return 1;
    }
    if (mode == CONTACT && net_contact_force(m, y) < 0.0) {
        m->S[S_VMODE] = FREE;
        m->out_valid = 0;
        return 1;
    }
    return 0;
}

/* ------------------------------------------------------------------------------------------ FMI 2.0 */
static void set_start_values(Model *m) {
    memset(m, 0, sizeof *m);
    for (int i = 0; i < N_PARAMS; i++) m->par[i] = START_PARAMS[i];
    m->blocked = START_BLOCKED;
    m->rtol = START_RTOL;
    m->V = START_V;
}

EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                                     const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)resources;
    (void)visible;
    if (!cb || !name) return NULL;
    if (!guid || strcmp(guid, MODEL_GUID) != 0) {
        if (cb->logger)
            cb->logger(cb->componentEnvironment, name, fmi2Error, "logStatusError",
                       "%s: wrong GUID (expected " MODEL_GUID ")", name);
        return NULL;
    }
    Instance *c = (Instance *)calloc(1, sizeof(Instance));
    if (!c) return NULL;
    c->cb = *cb;
    snprintf(c->name, sizeof c->name, "%s", name);
    c->logging = loggingOn;
    set_start_values(&c->m);
    c->me = type == fmi2ModelExchange;
    return c;
}

EXPORT void fmi2FreeInstance(fmi2Component comp) { free(comp); }

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean on, size_t n, const fmi2String cats[]) {
    (void)n;
    (void)cats;
    if (!comp) return fmi2Error;
    ((Instance *)comp)->logging = on;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                                      fmi2Boolean stopDefined, fmi2Real stop) {
    (void)tolDefined;
    (void)tol;
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    Model *m = &c->m;
    if (!isfinite(start) || (stopDefined && !isfinite(stop))) {
        ERROR(c, "fmi2SetupExperiment: %s %.17g is not a finite number", isfinite(start) ? "stopTime" : "startTime",
              isfinite(start) ? stop : start);
        return fmi2Error;
    }
    m->t0 = start;
    m->has_stop = stopDefined ? 1 : 0;
    m->stop_time = stop;
    if (stopDefined && !(stop >= start)) {
        m->has_stop = 0;
        ERROR(c, "fmi2SetupExperiment: stopTime %.17g is before startTime %.17g", stop, start);
        return fmi2Error;
    }
    return fmi2OK;
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component comp) { return comp ? fmi2OK : fmi2Error; }

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    Model *m = &c->m;
    m->initialized = 1;
    m->model_ok = 0;
    if (!check_parameters(c)) return fmi2Error;
    if (!setup_model(m)) {
        ERROR(c, "invalid parameter: parameters a = %.17g m, D = %.17g m, kB = %.17g T/A, r0 = %.17g m give a "
                 "non-finite force kernel", m->par[PI_a], m->par[PI_D], m->par[PI_kB], m->par[PI_r0]);
        return fmi2Error;
    }
    m->model_ok = 1;
    reset_integrator(m, m->t0);
    m->out_valid = 0;
    m->t_limit = m->has_stop ? m->stop_time + TIME_REL_TOL * (fabs(m->stop_time) + fabs(m->stop_time - m->t0))
                             : INFINITY;
    return fmi2OK;
}

EXPORT fmi2Status fmi2Terminate(fmi2Component comp) { return comp ? fmi2OK : fmi2Error; }

EXPORT fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    set_start_values(&c->m);
    return fmi2OK;
}

static void ensure_outputs(Model *m) {
    if (m->out_valid) return;
    if (!m->model_ok) {
        memset(m->out, 0, sizeof m->out);
    } else {
        outputs(m, ROW(m->W, W_VIEW), (int)m->S[S_VMODE], m->out);
    }
    m->out_valid = 1;
}

EXPORT fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    if (!c || (nvr && (!vr || !value))) return fmi2Error;
    Model *m = &c->m;
    for (size_t k = 0; k < nvr; k++) {
        int kind = vr[k] < N_VR ? VR_KIND[vr[k]] : VK_NONE, idx = vr[k] < N_VR ? VR_INDEX[vr[k]] : 0;
        if (kind == VK_INPUT) value[k] = m->V;
        else if (kind == VK_OUTPUT) {
            ensure_outputs(m);
            value[k] = m->out[idx];
        } else if (kind == VK_PARAM) value[k] = m->par[idx];
        else if (kind == VK_RTOL) value[k] = m->rtol;
        else if (kind == VK_STATE || kind == VK_DER) {
            double z[NMAX];
            if (kind == VK_STATE) me_get_z(m, z);
            else me_derivatives(m, z);
            value[k] = z[idx];
        } else {
            ERROR(c, "fmi2GetReal: no Real variable with value reference %u", vr[k]);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    if (!c || (nvr && (!vr || !value))) return fmi2Error;
    Model *m = &c->m;
    for (size_t k = 0; k < nvr; k++) {
        int kind = vr[k] < N_VR ? VR_KIND[vr[k]] : VK_NONE;
        if (kind == VK_BLOCKED) value[k] = m->blocked ? fmi2True : fmi2False;
        else if (kind == VK_CONTACT) {
            ensure_outputs(m);
            value[k] = m->out[5] != 0.0 ? fmi2True : fmi2False;
        } else {
            ERROR(c, "fmi2GetBoolean: no Boolean variable with value reference %u", vr[k]);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

/* FMI 2.0: a fixed parameter may be set only before fmi2ExitInitializationMode (StatusShimErrors._refuse_frozen) */
static int refuse_frozen(Instance *c, const fmi2ValueReference vr[], size_t nvr, const char *call) {
    if (!c->m.initialized) return 0;
    for (size_t k = 0; k < nvr; k++) {
        int kind = vr[k] < N_VR ? VR_KIND[vr[k]] : VK_NONE;
        if (kind == VK_PARAM || kind == VK_RTOL || kind == VK_BLOCKED) {
            ERROR(c, "%s: parameter %s has variability fixed: FMI 2.0 allows setting it only before and in "
                     "initialization mode (fmi2Reset, then set it before fmi2ExitInitializationMode); nothing was set",
                  call, VR_NAMES[vr[k]]);
            return 1;
        }
    }
    return 0;
}

EXPORT fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    if (!c || (nvr && (!vr || !value))) return fmi2Error;
    if (refuse_frozen(c, vr, nvr, "fmi2SetReal")) return fmi2Error;
    for (size_t k = 0; k < nvr; k++) {
        int kind = vr[k] < N_VR ? VR_KIND[vr[k]] : VK_NONE;
        if (kind != VK_INPUT && kind != VK_PARAM && kind != VK_RTOL) {
            ERROR(c, "fmi2SetReal: value reference %u is not a settable Real (input or parameter); nothing was set", vr[k]);
            return fmi2Error;
        }
    }
    Model *m = &c->m;
    for (size_t k = 0; k < nvr; k++) {
        int kind = VR_KIND[vr[k]], idx = VR_INDEX[vr[k]];
        if (kind == VK_INPUT) m->V = value[k];
        else if (kind == VK_PARAM) m->par[idx] = value[k];
        else m->rtol = value[k];
    }
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    if (!c || (nvr && (!vr || !value))) return fmi2Error;
    if (refuse_frozen(c, vr, nvr, "fmi2SetBoolean")) return fmi2Error;
    for (size_t k = 0; k < nvr; k++)
        if (!(vr[k] < N_VR && VR_KIND[vr[k]] == VK_BLOCKED)) {
            ERROR(c, "fmi2SetBoolean: value reference %u is not a settable Boolean; nothing was set", vr[k]);
            return fmi2Error;
        }
    for (size_t k = 0; k < nvr; k++) c->m.blocked = value[k] ? 1 : 0;
    return fmi2OK;
}

static fmi2Status no_variables(fmi2Component comp, size_t nvr, const char *call) {
    if (!comp) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    ERROR((Instance *)comp, "%s: the model has no such variables", call);
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer v[]) {
    (void)vr; (void)v;
    return no_variables(c, nvr, "fmi2GetInteger");
}
EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer v[]) {
    (void)vr; (void)v;
    return no_variables(c, nvr, "fmi2SetInteger");
}
EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String v[]) {
    (void)vr; (void)v;
    return no_variables(c, nvr, "fmi2GetString");
}
EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String v[]) {
    (void)vr; (void)v;
    return no_variables(c, nvr, "fmi2SetString");
}

EXPORT fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real current_time, fmi2Real step_size, fmi2Boolean noSetPrior) {
    (void)noSetPrior;
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    Model *m = &c->m;
    if (c->me) {
        ERROR(c, "fmi2DoStep: the instance was instantiated for model exchange");
        return fmi2Error;
    }
    if (!m->model_ok) {
        ERROR(c, "doStep before a successful initialization (see the earlier error)");
        return fmi2Error;
    }
    double t_end = current_time + step_size, t = m->t;
    int on_time = fabs(current_time - t) <= TIME_REL_TOL * (fabs(t) + fabs(step_size));
    if (!(on_time && t_end <= m->t_limit && step_size >= 0.0)) {
        if (!(step_size >= 0.0))
            ERROR(c, "doStep at t=%.17g (h=%.17g): communicationStepSize %.17g must be >= 0", current_time, step_size,
                  step_size);
        else if (!on_time)
            ERROR(c, "doStep at t=%.17g (h=%.17g): currentCommunicationPoint %.17g is not where the previous step "
                     "ended (%.17g): a skipped or repeated communication point", current_time, step_size, current_time, t);
        else
            ERROR(c, "doStep at t=%.17g (h=%.17g): the step ends at %.17g, after stopTime %.17g", current_time,
                  step_size, t_end, m->stop_time);
        return fmi2Error;
    }
    /* Integrator.advance */
    if (t_end < m->t - 1e-15) {
        ERROR(c, "doStep at t=%.17g (h=%.17g, V=%.17g) failed: ValueError: cannot integrate backwards", current_time,
              step_size, m->V);
        return fmi2Error;
    }
    int status = advance(m, t_end, m->V);
    if (status == ST_TOO_MANY_STEPS) {
        ERROR(c, "doStep at t=%.17g (h=%.17g, V=%.17g) failed: StepLimitError: more than %d internal steps from "
                 "t=%.17g s toward t=%.17g s (reached t=%.17g s; step bound %.17g s): the step is too long for the "
                 "model's time scales", current_time, step_size, m->V, MAX_STEPS_PER_ADVANCE, m->t, t_end, m->S[S_TF],
              m->S[P_MAXSTEP]);
        return fmi2Error;
    }
    if (status) {
        ERROR(c, "doStep at t=%.17g (h=%.17g, V=%.17g) failed: ArithmeticError: step size underflow at t=%.17g: the "
                 "model is not integrable here", current_time, step_size, m->V, m->S[S_TF]);
        return fmi2Error;
    }
    m->t = t_end;
    m->out_valid = 0;
    return fmi2OK;
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { return c ? fmi2OK : fmi2Error; }
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)order; (void)value;
    if (c) ERROR((Instance *)c, "fmi2SetRealInputDerivatives: not supported (canInterpolateInputs = false)");
    (void)nvr;
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)order; (void)value; (void)nvr;
    if (c) ERROR((Instance *)c, "fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder = 0)");
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                               const fmi2ValueReference z[], size_t nz, const fmi2Real du[],
                                               fmi2Real dz[]) {
    (void)u; (void)nu; (void)z; (void)nz; (void)du; (void)dz;
    if (c) ERROR((Instance *)c, "fmi2GetDirectionalDerivative: not supported (providesDirectionalDerivative = false)");
    return fmi2Error;
}
EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)s;
    if (!c || !v) return fmi2Error;
    *v = fmi2OK;
    return fmi2Discard;
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    if (!c || !v) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *v = ((Instance *)c)->m.t;
        return fmi2OK;
    }
    return fmi2Discard;
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)s; (void)v;
    return c ? fmi2Discard : fmi2Error;
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)s;
    if (!c || !v) return fmi2Error;
    *v = fmi2False;
    return s == fmi2Terminated ? fmi2OK : fmi2Discard;
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)s; (void)v;
    return c ? fmi2Discard : fmi2Error;
}

/* ---- FMU state: a copy of the Model (no pointers), serialized with a header naming the model ---- */
#define STATE_MAGIC "mpc_actuator_native-state/1"
typedef struct {
    char magic[32];
    char guid[64];
    Model m;
} SavedState;

/* a restored Model must be one a run can produce (model.check_restored_state, and the parameter checks) */
static int state_usable(Instance *c, const Model *m) {
    if (m->mask < 0 || m->mask >= N_MASKS || m->out_valid < 0 || m->out_valid > 1) return 0;
    if (!m->model_ok) return 1;
    const double *S = m->S;
    if (!isfinite(m->t) || S[S_T] != m->t || !(S[S_TF] >= S[S_T]) || !(S[S_H] >= 0.0)) return 0;
    int modes[3] = {S_MODE, S_VMODE, S_DMODE};
    for (int k = 0; k < 3; k++)
        if (!(S[modes[k]] == FREE || S[modes[k]] == CONTACT || S[modes[k]] == BLOCKED)) return 0;
    for (int i = 0; i < NW * NMAX; i++)
        if (!isfinite(m->W[i])) return 0;
    if (!(ROW(m->W, W_Y)[1] <= m->par[PI_r0]) || !(ROW(m->W, W_VIEW)[1] <= m->par[PI_r0])) return 0;
    /* the parameter block must be the one these parameters give */
    Model fresh = *m;
    if (!setup_model(&fresh)) return 0;
    if (memcmp(fresh.S, m->S, NP * sizeof(double)) || memcmp(fresh.coef, m->coef, sizeof m->coef)) return 0;
    (void)c;
    return 1;
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    Instance *c = (Instance *)comp;
    if (!c || !state) return fmi2Error;
    SavedState *s = *state ? (SavedState *)*state : (SavedState *)calloc(1, sizeof(SavedState));
    if (!s) {
        ERROR(c, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    snprintf(s->magic, sizeof s->magic, "%s", STATE_MAGIC);
    snprintf(s->guid, sizeof s->guid, "%s", MODEL_GUID);
    s->m = c->m;
    *state = s;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    SavedState *s = (SavedState *)state;
    if (!s || strcmp(s->magic, STATE_MAGIC) != 0 || strcmp(s->guid, MODEL_GUID) != 0 || !state_usable(c, &s->m)) {
        ERROR(c, "fmi2SetFMUstate: not a usable state of this model");
        return fmi2Error;
    }
    c->m = s->m;
    return fmi2OK;
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    if (!comp || !state) return fmi2Error;
    SavedState *s = (SavedState *)*state;
    if (s) {
        memset(s->magic, 0, sizeof s->magic); /* a freed state is not usable (if the memory is still read) */
        free(s);
    }
    *state = NULL;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    if (!comp || !state || !size) return fmi2Error;
    *size = sizeof(SavedState);
    return fmi2OK;
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    Instance *c = (Instance *)comp;
    if (!c || !state || !bytes) return fmi2Error;
    if (size < sizeof(SavedState)) {
        ERROR(c, "fmi2SerializeFMUstate: %zu bytes given, %zu needed", size, sizeof(SavedState));
        return fmi2Error;
    }
    memcpy(bytes, state, sizeof(SavedState));
    return fmi2OK;
}

EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size,
                                          fmi2FMUstate *state) {
    Instance *c = (Instance *)comp;
    if (!c || !bytes || !state) return fmi2Error;
    if (size != sizeof(SavedState)) {
        ERROR(c, "fmi2DeSerializeFMUstate: %zu bytes, a state of this model has %zu", size, sizeof(SavedState));
        return fmi2Error;
    }
    SavedState *s = (SavedState *)malloc(sizeof(SavedState));
    if (!s) return fmi2Error;
    memcpy(s, bytes, sizeof(SavedState));
    s->magic[sizeof s->magic - 1] = s->guid[sizeof s->guid - 1] = 0;
    if (strcmp(s->magic, STATE_MAGIC) != 0 || strcmp(s->guid, MODEL_GUID) != 0 || !state_usable(c, &s->m)) {
        free(s);
        ERROR(c, "fmi2DeSerializeFMUstate: not a serialized state of this model");
        return fmi2Error;
    }
    if (*state) free(*state);
    *state = s;
    return fmi2OK;
}

/* ---- for the tests (not FMI): the integrator's arrays, to compare with fmu_src.model.Integrator ---- */
EXPORT int mpc_native_debug_arrays(fmi2Component comp, double *S, double *W, double *coef) {
    Instance *c = (Instance *)comp;
    if (!c || !c->m.model_ok) return -1;
    int n = (int)c->m.S[P_N];
    if (S) memcpy(S, c->m.S, sizeof c->m.S);
    if (W)
        for (int r = 0; r < NW; r++)
            for (int i = 0; i < n; i++) W[r * n + i] = ROW(c->m.W, r)[i];
    if (coef) memcpy(coef, c->m.coef, sizeof c->m.coef);
    return n;
}

/* for the tests (not FMI): set the integrator's arrays (S beyond the parameter block, W rows of n) and take one
   internal step toward t_end (integrator.py's _step); returns its status */
EXPORT int mpc_native_debug_set_step(fmi2Component comp, const double *S, const double *W, int take_step,
                                     double t_end) {
    Instance *c = (Instance *)comp;
    if (!c || !c->m.model_ok) return -1;
    int n = (int)c->m.S[P_N];
    if (S) memcpy(c->m.S + NP, S + NP, (NS - NP) * sizeof(double));
    if (W)
        for (int r = 0; r < NW; r++)
            for (int i = 0; i < n; i++) ROW(c->m.W, r)[i] = W[r * n + i];
    return take_step ? step(&c->m, t_end) : 0;
}

/* ---- model exchange ---- */
static Instance *me_instance(fmi2Component comp, const char *call) {
    Instance *c = (Instance *)comp;
    if (!c) return NULL;
    if (!c->me || !c->m.model_ok) {
        ERROR(c, "%s: %s", call, c->me ? "before a successful initialization" : "the instance is for co-simulation");
        return NULL;
    }
    return c;
}
EXPORT fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    return me_instance(comp, "fmi2EnterEventMode") ? fmi2OK : fmi2Error;
}
EXPORT fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    Instance *c = me_instance(comp, "fmi2NewDiscreteStates");
    if (!c || !info) return fmi2Error;
    int changed = me_events(&c->m);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = changed ? fmi2True : fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}
EXPORT fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    return me_instance(comp, "fmi2EnterContinuousTimeMode") ? fmi2OK : fmi2Error;
}
EXPORT fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetPrior, fmi2Boolean *enterEventMode,
                                              fmi2Boolean *terminateSimulation) {
    (void)noSetPrior;
    if (!me_instance(comp, "fmi2CompletedIntegratorStep") || !enterEventMode || !terminateSimulation) return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}
EXPORT fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    Instance *c = (Instance *)comp;
    if (!c) return fmi2Error;
    c->m.t = time;
    return fmi2OK;
}
EXPORT fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Instance *c = me_instance(comp, "fmi2SetContinuousStates");
    if (!c || !x || nx != N_ME_STATES) return fmi2Error;
    me_set_z(&c->m, x);
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!c || !x || nx != N_ME_STATES) return fmi2Error;
    me_get_z(&c->m, x);
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real dx[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!c || !dx || nx != N_ME_STATES) return fmi2Error;
    me_derivatives(&c->m, dx);
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real ind[], size_t ni) {
    Instance *c = (Instance *)comp;
    if (!c || !ind || ni != 1) return fmi2Error;
    ind[0] = c->m.model_ok ? me_indicator(&c->m) : 1.0;
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real nominal[], size_t nx) {
    if (!comp || !nominal || nx != N_ME_STATES) return fmi2Error;
    for (size_t i = 0; i < nx; i++) nominal[i] = 1.0;
    return fmi2OK;
}
