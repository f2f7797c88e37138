/*
 * fmi2_cs_host.c -- a minimal FMI 2.0 co-simulation host in C (a worked example for non-Python hosts).
 *
 *   fmi2_cs_host FMU_DIR --step H --stop T --output VR[,VR...] RUN [RUN ...]
 *   RUN:  --instance NAME [--input VR=V0 [--sine F]] [VR=VALUE ...] [--reset [VR=VALUE ...]]
 *
 * FMU_DIR is an unzipped FMU. The host reads the GUID and the co-simulation modelIdentifier from
 * modelDescription.xml, dlopens binaries/linux64/<modelIdentifier>.so and gets the functions with dlsym.
 * Each RUN is one instance: VR=VALUE sets a Real parameter (after fmi2SetupExperiment, before
 * fmi2EnterInitializationMode), --input sets the Real input VR to V0 in initialization mode and before every
 * step (--sine: V(t) = V0*sin(2*pi*F*t), sampled at the communication point t and held over the step).
 * With --reset, an fmi2Error during initialization is followed by fmi2Reset and a second initialization
 * with the parameters after --reset. All instances step on the same grid t_k = k*H (k = 0 .. round(T/H)),
 * interleaved (the order alternates from step to step). stdout: a CSV "time,NAME:VR,..." with a row at
 * every communication point (outputs read with fmi2GetReal).
 *
 * stderr: the FMU's log messages (loggingOn = fmi2False: the FMU sends warnings and errors anyway) and one
 * line "fmi2_cs_host: <function>(<instance>) returned status <n> (<name>)" for every non-OK status.
 * Exit codes: 0 success (also after an error that fmi2Reset recovered), 1 usage, 2 FMU not loadable,
 * 3 fmi2Instantiate failed, 10 + status when a function returned fmi2Discard or worse (13: fmi2Error,
 * 14: fmi2Fatal). Instances are freed at the end (not after fmi2Fatal, as FMI 2.0 requires), the library is
 * closed and main returns: the process exits normally (the FMU's status shim shuts the embedded Python down
 * in an atexit handler, before SciPy's C++ destructors; see fmu_shim/fmi2_status_shim.c).
 *
 * A pythonfmu FMU needs libpython in the process and its Python packages importable: see README.md (FMU)
 * and tests/fmu/test_c_host.py for the environment. Build (-ffp-contract=off: no fused multiply-add, so that
 * the sine input equals Python's V0*math.sin(2*math.pi*F*t) bit for bit):
 *   cc -std=c11 -O2 -Wall -Wextra -ffp-contract=off -o fmi2_cs_host fmi2_cs_host.c -ldl -lm
 */
#define _XOPEN_SOURCE 700 /* realpath */
#include <dlfcn.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h) ---- */
typedef void* fmi2Component;
typedef void* fmi2ComponentEnvironment;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char* fmi2String;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef struct {
    void (*logger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void* (*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void*);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

static struct {
    fmi2String (*GetVersion)(void);
    fmi2Component (*Instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions*,
                                 fmi2Boolean, fmi2Boolean);
    void (*FreeInstance)(fmi2Component);
    fmi2Status (*SetupExperiment)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
    fmi2Status (*EnterInitializationMode)(fmi2Component);
    fmi2Status (*ExitInitializationMode)(fmi2Component);
    fmi2Status (*Terminate)(fmi2Component);
    fmi2Status (*Reset)(fmi2Component);
    fmi2Status (*GetReal)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[]);
    fmi2Status (*SetReal)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]);
    fmi2Status (*DoStep)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
} fmi;

#define MAX_INST 8
#define MAX_VARS 64
#define PI 3.14159265358979323846

typedef struct { size_t n; fmi2ValueReference vr[MAX_VARS]; fmi2Real value[MAX_VARS]; } Values;

typedef struct {
    const char* name;
    fmi2Component c;
    int has_input, has_reset;
    fmi2ValueReference input_vr;
    double V0, freq;           /* freq 0: constant input V0 */
    Values params, reset_params;
} Instance;

static const char* STATUS_NAMES[] = {"fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal",
                                     "fmi2Pending"};

static const char* status_name(fmi2Status s) { return (unsigned)s < 6 ? STATUS_NAMES[s] : "?"; }

/* the FMU's logger: message is a printf format for the variable arguments */
static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list ap;
    (void)env;
    fprintf(stderr, "[%s %d] %s (%s): ", status_name(status), (int)status, instance ? instance : "?",
            category ? category : "");
    va_start(ap, message);
    vfprintf(stderr, message ? message : "", ap);
    va_end(ap);
    fputc('\n', stderr);
}

/* report a non-OK status; returns 1 when the host can carry on (fmi2OK, fmi2Warning) */
static int ok(fmi2Status st, const char* function, const Instance* in) {
    if (st != fmi2OK)
        fprintf(stderr, "fmi2_cs_host: %s(%s) returned status %d (%s)\n", function, in->name, (int)st,
                status_name(st));
    return st <= fmi2Warning;
}

static void usage(const char* why) {
    fprintf(stderr, "fmi2_cs_host: %s\nusage: fmi2_cs_host FMU_DIR --step H --stop T --output VR[,VR...] "
                    "RUN [RUN ...]\n  RUN: --instance NAME [--input VR=V0 [--sine F]] "
                    "[VR=VALUE ...] [--reset [VR=VALUE ...]]\n", why);
    exit(1);
}

static double number(const char* s) {
    char* end;
    double v = strtod(s, &end);
    if (end == s || *end) usage("not a number");
    return v;
}

static void add_value(Values* v, const char* arg) { /* "VR=VALUE" */
    char* end;
    unsigned long vr = strtoul(arg, &end, 10);
    if (end == arg || *end != '=' || v->n == MAX_VARS) usage("expected VR=VALUE");
    v->vr[v->n] = (fmi2ValueReference)vr;
    v->value[v->n++] = number(end + 1);
}

/* the value of attribute `attr` of the first element `element` in `xml` (static buffer) */
static const char* xml_attr(const char* xml, const char* element, const char* attr) {
    static char value[512];
    char key[64];
    const char* p = strstr(xml, element);
    const char* close = p ? strchr(p, '>') : NULL;
    snprintf(key, sizeof key, " %s=\"", attr);
    const char* a = p ? strstr(p, key) : NULL;
    if (!a || !close || a > close) return NULL;
    a += strlen(key);
    size_t n = strcspn(a, "\"");
    if (n >= sizeof value) return NULL;
    memcpy(value, a, n);
    value[n] = '\0';
    return value;
}

static int load_symbol(void* lib, const char* name, void* fp, size_t size) {
    void* p = dlsym(lib, name);
    if (!p) fprintf(stderr, "fmi2_cs_host: %s not found: %s\n", name, dlerror());
    else memcpy(fp, &p, size); /* object pointer -> function pointer (POSIX) */
    return p != NULL;
}

static fmi2Status set_input(Instance* in, double t) {
    fmi2Real V = in->freq != 0.0 ? in->V0 * sin(2.0 * PI * in->freq * t) : in->V0;
    return in->has_input ? fmi.SetReal(in->c, &in->input_vr, 1, &V) : fmi2OK;
}

/* setup, parameters, initialization mode with the input at t0; returns the first non-OK status (or OK) */
static fmi2Status initialize(Instance* in, const Values* p, double t0, double stop) {
    fmi2Status st;
    if (!ok(st = fmi.SetupExperiment(in->c, 0, 0.0, t0, 1, stop), "fmi2SetupExperiment", in)) return st;
    if (p->n && !ok(st = fmi.SetReal(in->c, p->vr, p->n, p->value), "fmi2SetReal", in)) return st;
    if (!ok(st = fmi.EnterInitializationMode(in->c), "fmi2EnterInitializationMode", in)) return st;
    if (!ok(st = set_input(in, t0), "fmi2SetReal", in)) return st;
    ok(st = fmi.ExitInitializationMode(in->c), "fmi2ExitInitializationMode", in);
    return st;
}

int main(int argc, char** argv) {
    Instance inst[MAX_INST];
    size_t n_inst = 0, n_out = 0;
    fmi2ValueReference out[MAX_VARS];
    double h = 0.0, stop = 0.0, t0 = 0.0;
    Values* target = NULL;
    memset(inst, 0, sizeof inst);

    if (argc < 2) usage("no FMU directory");
    for (int i = 2; i < argc; ++i) {
        const char* a = argv[i];
        Instance* in = n_inst ? &inst[n_inst - 1] : NULL;
        int more = i + 1 < argc;
        if (!strcmp(a, "--step") && more) h = number(argv[++i]);
        else if (!strcmp(a, "--stop") && more) stop = number(argv[++i]);
        else if (!strcmp(a, "--output") && more) {
            for (char* tok = strtok(argv[++i], ","); tok; tok = strtok(NULL, ",")) {
                if (n_out == MAX_VARS) usage("too many outputs");
                out[n_out++] = (fmi2ValueReference)number(tok);
            }
        } else if (!strcmp(a, "--instance") && more) {
            if (n_inst == MAX_INST) usage("too many instances");
            inst[n_inst].name = argv[++i];
            target = &inst[n_inst++].params;
        } else if (!in) usage("--instance NAME must come before instance options");
        else if (!strcmp(a, "--input") && more) {
            Values v = {0};
            add_value(&v, argv[++i]);
            in->has_input = 1;
            in->input_vr = v.vr[0];
            in->V0 = v.value[0];
        } else if (!strcmp(a, "--sine") && more) in->freq = number(argv[++i]);
        else if (!strcmp(a, "--reset")) {
            in->has_reset = 1;
            target = &in->reset_params;
        } else add_value(target, a);
    }
    if (!(h > 0.0) || !(stop > t0) || !n_inst || !n_out) usage("need --step > 0, --stop > 0, --output, a RUN");
    long n_steps = lround((stop - t0) / h);

    /* modelDescription.xml: GUID and modelIdentifier */
    char dir[PATH_MAX], path[PATH_MAX + 600], guid[512], id[512], resources[PATH_MAX + 64];
    if (!realpath(argv[1], dir)) { perror(argv[1]); return 2; }
    snprintf(path, sizeof path, "%s/modelDescription.xml", dir);
    FILE* f = fopen(path, "rb");
    if (!f) { perror(path); return 2; }
    static char xml[1 << 20];
    xml[fread(xml, 1, sizeof xml - 1, f)] = '\0';
    fclose(f);
    const char* s;
    if (!(s = xml_attr(xml, "<fmiModelDescription", "guid"))) { fprintf(stderr, "no guid\n"); return 2; }
    snprintf(guid, sizeof guid, "%s", s);
    if (!(s = xml_attr(xml, "<CoSimulation", "modelIdentifier"))) { fprintf(stderr, "not CS\n"); return 2; }
    snprintf(id, sizeof id, "%s", s);

    /* the binary and its functions */
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "fmi2_cs_host: dlopen: %s\n", dlerror()); return 2; }
#define LOAD(fn) load_symbol(lib, "fmi2" #fn, &fmi.fn, sizeof fmi.fn)
    if (!(LOAD(GetVersion) & LOAD(Instantiate) & LOAD(FreeInstance) & LOAD(SetupExperiment) &
          LOAD(EnterInitializationMode) & LOAD(ExitInitializationMode) & LOAD(Terminate) & LOAD(Reset) &
          LOAD(GetReal) & LOAD(SetReal) & LOAD(DoStep))) return 2;
#undef LOAD
    if (strcmp(fmi.GetVersion(), "2.0") != 0) { fprintf(stderr, "fmi2_cs_host: not FMI 2.0\n"); return 2; }

    /* instantiate (the FMU may keep a pointer to the callbacks: static) and initialize */
    static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    snprintf(resources, sizeof resources, "file://%s/resources", dir);
    fmi2Status st = fmi2OK;
    int rc = 0;
    size_t n_live = 0;
    for (; n_live < n_inst; ++n_live) {
        Instance* in = &inst[n_live];
        in->c = fmi.Instantiate(in->name, fmi2CoSimulation, guid, resources, &callbacks, 0, 0);
        if (!in->c) { fprintf(stderr, "fmi2_cs_host: fmi2Instantiate(%s) failed\n", in->name); rc = 3; goto done; }
    }
    for (size_t i = 0; i < n_inst; ++i) {
        Instance* in = &inst[i];
        st = initialize(in, &in->params, t0, stop);
        if (st == fmi2Error && in->has_reset) {   /* e.g. an invalid parameter: start over */
            if (!ok(st = fmi.Reset(in->c), "fmi2Reset", in)) goto failed;
            st = initialize(in, &in->reset_params, t0, stop);
        }
        if (st > fmi2Warning) goto failed;
    }

    /* simulate: header, a row at t0 and after every step */
    printf("time");
    for (size_t i = 0; i < n_inst; ++i)
        for (size_t j = 0; j < n_out; ++j) printf(",%s:%u", inst[i].name, out[j]);
    for (long k = 0;; ++k) {
        double t = t0 + (double)k * h;   /* as fmpy: start + n*interval, step = t_{k+1} - t_k */
        fmi2Real y[MAX_VARS];
        printf("\n%.17g", t);
        for (size_t i = 0; i < n_inst; ++i) {
            if (!ok(st = fmi.GetReal(inst[i].c, out, n_out, y), "fmi2GetReal", &inst[i])) goto failed;
            for (size_t j = 0; j < n_out; ++j) printf(",%.17g", y[j]);
        }
        if (k == n_steps) break;
        double t_next = t0 + (double)(k + 1) * h;
        for (size_t m = 0; m < n_inst; ++m) {
            Instance* in = &inst[k % 2 ? n_inst - 1 - m : m];   /* interleaved, alternating order */
            if (!ok(st = set_input(in, t), "fmi2SetReal", in)) goto failed;
            if (!ok(st = fmi.DoStep(in->c, t, t_next - t, 1), "fmi2DoStep", in)) goto failed;
        }
    }
    printf("\n");
    for (size_t i = 0; i < n_inst; ++i)
        if (!ok(st = fmi.Terminate(inst[i].c), "fmi2Terminate", &inst[i])) goto failed;
    goto done;

failed:
    rc = 10 + (int)st;
    if (st == fmi2Fatal) n_live = 0;   /* FMI 2.0: after fmi2Fatal no function may be called */
done:
    for (size_t i = 0; i < n_live; ++i) fmi.FreeInstance(inst[i].c);
    dlclose(lib);
    return rc;
}
