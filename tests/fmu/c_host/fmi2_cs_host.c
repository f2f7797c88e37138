/*
 * fmi2_cs_host.c -- a minimal FMI 2.0 co-simulation host in C (a worked example for non-Python hosts).
 *
 *   fmi2_cs_host FMU_DIR --step H --stop T [--unload reverse|forward|none] --output VR[,VR...] RUN [RUN ...]
 *                [--fmu FMU_DIR [--output VR[,VR...]] RUN ...]
 *   RUN:  --instance NAME [--input VR=V0 [--sine F]] [VR=VALUE ...] [--reset [VR=VALUE ...]]
 *         [--state-check K]
 *
 * FMU_DIR is an unzipped FMU. The host reads the GUID and the co-simulation modelIdentifier from
 * modelDescription.xml, dlopens binaries/linux64/<modelIdentifier>.so and gets the functions with dlsym
 * (on Windows: LoadLibrary of binaries/win64/<modelIdentifier>.dll, GetProcAddress).
 * Several FMUs can be given (--fmu starts the next one; its RUNs follow): they are loaded and their instances
 * instantiated in the order given, and the libraries are closed at the end in the order --unload says
 * (reverse: last loaded first, the default; forward: first loaded first; none: not closed, the process exits
 * with them loaded, as some tools do).
 * Each RUN is one instance of the current FMU, with the current --output list: VR=VALUE sets a Real parameter
 * (after fmi2SetupExperiment, before fmi2EnterInitializationMode), --input sets the Real input VR to V0 in
 * initialization mode and before every step (--sine: V(t) = V0*sin(2*pi*F*t), sampled at the communication
 * point t and held over the step). With --reset, an fmi2Error during initialization is followed by fmi2Reset
 * and a second initialization with the parameters after --reset. All instances step on the same grid
 * t_k = k*H (k = 0 .. round(T/H)), interleaved (the order alternates from step to step). stdout: a CSV
 * "time,NAME:VR,..." with a row at every communication point (outputs read with fmi2GetReal).
 *
 * --state-check K (FMU state save/restore) before the step from t_K: fmi2GetFMUstate; the step; the outputs;
 * fmi2SetFMUstate; the step again: the outputs must be bit-identical. Then the state is serialized, a fresh
 * instance is instantiated and initialized, the bytes are deserialized and set into it, and both take the
 * step: bit-identical again (the fresh instance is then freed). Then the error paths: a freed state, garbage
 * bytes, a truncated serialization and a NULL state must each give fmi2Error (not a crash, not fmi2Fatal).
 * One line "state-check NAME: ..." per check on stderr; a failed check exits with 20.
 *
 * stderr: the FMU's log messages (loggingOn = fmi2False: the FMU sends warnings and errors anyway) and one
 * line "fmi2_cs_host: <function>(<instance>) returned status <n> (<name>)" for every non-OK status.
 * The logger rejects NULL string arguments the way a C++ host that builds std::string from them does
 * (OMSimulator: "basic_string: construction from null is not valid"): it abort()s.
 * Exit codes: 0 success (also after an error that fmi2Reset recovered), 1 usage, 2 FMU not loadable,
 * 3 fmi2Instantiate failed, 10 + status when a function returned fmi2Discard or worse (13: fmi2Error,
 * 14: fmi2Fatal), 20 a failed --state-check. Instances are freed at the end (not after fmi2Fatal, as FMI 2.0
 * requires), the libraries are closed and main returns: the process exits normally.
 *
 * A pythonfmu FMU needs libpython in the process and its Python packages importable: the actuator's status
 * shim finds them itself (resources/python.json, or MPC_ACTUATOR_PYTHON; see README.md). Build
 * (-ffp-contract=off: no fused multiply-add, so that the sine input equals Python's
 * V0*math.sin(2*math.pi*F*t) bit for bit):
 *   cc -std=c11 -O2 -Wall -Wextra -ffp-contract=off -o fmi2_cs_host fmi2_cs_host.c -ldl -lm
 */
#define _XOPEN_SOURCE 700 /* realpath */
#ifdef _WIN32 /* the same host for win64 (cross-compiled with zig cc, run under wine): LoadLibrary for dlopen */
#include <windows.h>
#define RTLD_NOW 0
#define RTLD_LOCAL 0
#ifndef PATH_MAX
#define PATH_MAX MAX_PATH
#endif
#define dlopen(path, flags) ((void*)LoadLibraryA(path))
#define dlsym(lib, name) ((void*)GetProcAddress((HMODULE)(lib), (name)))
#define dlclose(lib) FreeLibrary((HMODULE)(lib))
#define dlerror() "LoadLibrary/GetProcAddress failed"
#define realpath(path, out) _fullpath((out), (path), MAX_PATH)
#define PLATFORM_LIB "binaries/win64/%s.dll"
#else
#include <dlfcn.h>
#define PLATFORM_LIB "binaries/linux64/%s.so"
#endif
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h) ---- */
typedef void* fmi2Component;
typedef void* fmi2ComponentEnvironment;
typedef void* fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef char fmi2Byte;
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

typedef struct {
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
    /* optional (--state-check) */
    fmi2Status (*GetFMUstate)(fmi2Component, fmi2FMUstate*);
    fmi2Status (*SetFMUstate)(fmi2Component, fmi2FMUstate);
    fmi2Status (*FreeFMUstate)(fmi2Component, fmi2FMUstate*);
    fmi2Status (*SerializedFMUstateSize)(fmi2Component, fmi2FMUstate, size_t*);
    fmi2Status (*SerializeFMUstate)(fmi2Component, fmi2FMUstate, fmi2Byte[], size_t);
    fmi2Status (*DeSerializeFMUstate)(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate*);
} Api;

#define MAX_FMU 4
#define MAX_INST 8
#define MAX_VARS 64
#define PI 3.14159265358979323846

typedef struct {
    const char* arg;   /* FMU_DIR as given */
    char dir[PATH_MAX], guid[512], id[512], resources[PATH_MAX + 64];
    void* lib;
    Api fmi;
} Fmu;

typedef struct { size_t n; fmi2ValueReference vr[MAX_VARS]; fmi2Real value[MAX_VARS]; } Values;

typedef struct {
    const char* name;
    Fmu* fmu;
    fmi2Component c;
    int has_input, has_reset;
    fmi2ValueReference input_vr;
    double V0, freq;           /* freq 0: constant input V0 */
    Values params, reset_params;
    size_t n_out;
    fmi2ValueReference out[MAX_VARS];
    long state_check;          /* step index for --state-check, -1: none */
} Instance;

static const char* STATUS_NAMES[] = {"fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal",
                                     "fmi2Pending"};

static const char* status_name(fmi2Status s) { return (unsigned)s < 6 ? STATUS_NAMES[s] : "?"; }

/* the FMU's logger: message is a printf format for the variable arguments. Like a C++ host that makes
 * std::string of its arguments, it does not accept NULL for any string argument: abort(). */
static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list ap;
    (void)env;
    if (!instance || !category || !message) {
        fprintf(stderr, "fmi2_cs_host: logger called with a NULL %s: abort()\n",
                !instance ? "instanceName" : !category ? "category" : "message");
        abort();
    }
    fprintf(stderr, "[%s %d] %s (%s): ", status_name(status), (int)status, instance, category);
    va_start(ap, message);
    vfprintf(stderr, message, ap);
    va_end(ap);
    fputc('\n', stderr);
}

/* the FMU may keep a pointer to the callbacks: static */
static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

/* report a non-OK status; returns 1 when the host can carry on (fmi2OK, fmi2Warning) */
static int ok(fmi2Status st, const char* function, const Instance* in) {
    if (st != fmi2OK)
        fprintf(stderr, "fmi2_cs_host: %s(%s) returned status %d (%s)\n", function, in->name, (int)st,
                status_name(st));
    return st <= fmi2Warning;
}

static void usage(const char* why) {
    fprintf(stderr, "fmi2_cs_host: %s\nusage: fmi2_cs_host FMU_DIR --step H --stop T [--unload reverse|forward|"
                    "none] --output VR[,VR...] RUN [RUN ...] [--fmu FMU_DIR [--output ...] RUN ...]\n"
                    "  RUN: --instance NAME [--input VR=V0 [--sine F]] [VR=VALUE ...] [--reset [VR=VALUE ...]] "
                    "[--state-check K]\n", why);
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

static int load_symbol(void* lib, const char* name, void* fp, size_t size, int required) {
    void* p = dlsym(lib, name);
    if (!p && required) fprintf(stderr, "fmi2_cs_host: %s not found: %s\n", name, dlerror());
    else if (p) memcpy(fp, &p, size); /* object pointer -> function pointer (POSIX) */
    return p != NULL || !required;
}

/* modelDescription.xml (GUID, modelIdentifier), dlopen, dlsym; returns 0 or the exit code 2 */
static int load_fmu(Fmu* f) {
    char path[PATH_MAX + 600];
    if (!realpath(f->arg, f->dir)) { perror(f->arg); return 2; }
    snprintf(path, sizeof path, "%s/modelDescription.xml", f->dir);
    FILE* fp = fopen(path, "rb");
    if (!fp) { perror(path); return 2; }
    static char xml[1 << 20];
    xml[fread(xml, 1, sizeof xml - 1, fp)] = '\0';
    fclose(fp);
    const char* s;
    if (!(s = xml_attr(xml, "<fmiModelDescription", "guid"))) { fprintf(stderr, "no guid\n"); return 2; }
    snprintf(f->guid, sizeof f->guid, "%s", s);
    if (!(s = xml_attr(xml, "<CoSimulation", "modelIdentifier"))) { fprintf(stderr, "not CS\n"); return 2; }
    snprintf(f->id, sizeof f->id, "%s", s);
    snprintf(f->resources, sizeof f->resources, "file://%s/resources", f->dir);

    snprintf(path, sizeof path, "%s/" PLATFORM_LIB, f->dir, f->id);
    f->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!f->lib) { fprintf(stderr, "fmi2_cs_host: dlopen: %s\n", dlerror()); return 2; }
#define LOAD(fn) load_symbol(f->lib, "fmi2" #fn, &f->fmi.fn, sizeof f->fmi.fn, 1)
#define LOAD_OPT(fn) load_symbol(f->lib, "fmi2" #fn, &f->fmi.fn, sizeof f->fmi.fn, 0)
    if (!(LOAD(GetVersion) & LOAD(Instantiate) & LOAD(FreeInstance) & LOAD(SetupExperiment) &
          LOAD(EnterInitializationMode) & LOAD(ExitInitializationMode) & LOAD(Terminate) & LOAD(Reset) &
          LOAD(GetReal) & LOAD(SetReal) & LOAD(DoStep))) return 2;
    LOAD_OPT(GetFMUstate); LOAD_OPT(SetFMUstate); LOAD_OPT(FreeFMUstate); LOAD_OPT(SerializedFMUstateSize);
    LOAD_OPT(SerializeFMUstate); LOAD_OPT(DeSerializeFMUstate);
#undef LOAD
#undef LOAD_OPT
    if (strcmp(f->fmi.GetVersion(), "2.0") != 0) { fprintf(stderr, "fmi2_cs_host: not FMI 2.0\n"); return 2; }
    return 0;
}

static fmi2Status set_input(Instance* in, double t) {
    fmi2Real V = in->freq != 0.0 ? in->V0 * sin(2.0 * PI * in->freq * t) : in->V0;
    return in->has_input ? in->fmu->fmi.SetReal(in->c, &in->input_vr, 1, &V) : fmi2OK;
}

/* setup, parameters, initialization mode with the input at t0; returns the first non-OK status (or OK) */
static fmi2Status initialize(Instance* in, const Values* p, double t0, double stop) {
    const Api* fmi = &in->fmu->fmi;
    fmi2Status st;
    if (!ok(st = fmi->SetupExperiment(in->c, 0, 0.0, t0, 1, stop), "fmi2SetupExperiment", in)) return st;
    if (p->n && !ok(st = fmi->SetReal(in->c, p->vr, p->n, p->value), "fmi2SetReal", in)) return st;
    if (!ok(st = fmi->EnterInitializationMode(in->c), "fmi2EnterInitializationMode", in)) return st;
    if (!ok(st = set_input(in, t0), "fmi2SetReal", in)) return st;
    ok(st = fmi->ExitInitializationMode(in->c), "fmi2ExitInitializationMode", in);
    return st;
}

/* one step of `in` from t to t_next with its input; the outputs into y; returns the status */
static fmi2Status step_and_read(Instance* in, double t, double t_next, fmi2Real y[]) {
    fmi2Status st;
    if (!ok(st = set_input(in, t), "fmi2SetReal", in)) return st;
    if (!ok(st = in->fmu->fmi.DoStep(in->c, t, t_next - t, 0), "fmi2DoStep", in)) return st;
    ok(st = in->fmu->fmi.GetReal(in->c, in->out, in->n_out, y), "fmi2GetReal", in);
    return st;
}

static int report(const Instance* in, const char* what, int good) {
    fprintf(stderr, "state-check %s: %s: %s\n", in->name, what, good ? "ok" : "FAILED");
    return good;
}

/* --state-check (see the header); returns 1 when every check passed. The instance is left at t (state set
 * back), so the main loop's own step continues as if nothing had happened. */
static int state_check(Instance* in, double t0, double stop, double t, double t_next) {
    const Api* fmi = &in->fmu->fmi;
    fmi2Real y1[MAX_VARS], y2[MAX_VARS], y3[MAX_VARS];
    fmi2FMUstate s = NULL, s2 = NULL;
    size_t n = 0;
    int good = 1;
    if (!fmi->GetFMUstate || !fmi->DeSerializeFMUstate) return report(in, "FMU exports the state functions", 0);
    /* 1. get, step, set, step: bit-identical */
    good &= report(in, "fmi2GetFMUstate", fmi->GetFMUstate(in->c, &s) == fmi2OK && s != NULL);
    if (!good) return 0;
    good &= report(in, "step", step_and_read(in, t, t_next, y1) == fmi2OK);
    good &= report(in, "fmi2SetFMUstate", fmi->SetFMUstate(in->c, s) == fmi2OK);
    good &= report(in, "step again", step_and_read(in, t, t_next, y2) == fmi2OK);
    good &= report(in, "rollback: bit-identical outputs", memcmp(y1, y2, in->n_out * sizeof y1[0]) == 0);
    /* 2. serialize, deserialize into a fresh instance: it continues identically */
    good &= report(in, "fmi2SerializedFMUstateSize", fmi->SerializedFMUstateSize(in->c, s, &n) == fmi2OK && n > 0);
    fmi2Byte* bytes = (fmi2Byte*)malloc(n ? n : 1);
    good &= report(in, "fmi2SerializeFMUstate", bytes && fmi->SerializeFMUstate(in->c, s, bytes, n) == fmi2OK);
    Instance fresh = *in;
    fresh.name = "fresh";
    fresh.c = fmi->Instantiate("fresh", fmi2CoSimulation, in->fmu->guid, in->fmu->resources, &callbacks, 0, 0);
    good &= report(in, "fresh instance", fresh.c && initialize(&fresh, &in->params, t0, stop) == fmi2OK);
    if (fresh.c) {
        good &= report(in, "fmi2DeSerializeFMUstate", fmi->DeSerializeFMUstate(fresh.c, bytes, n, &s2) == fmi2OK);
        good &= report(in, "fmi2SetFMUstate (fresh)", fmi->SetFMUstate(fresh.c, s2) == fmi2OK);
        good &= report(in, "step (fresh)", step_and_read(&fresh, t, t_next, y3) == fmi2OK);
        good &= report(in, "fresh instance: bit-identical outputs", memcmp(y1, y3, in->n_out * sizeof y1[0]) == 0);
        fmi->FreeFMUstate(fresh.c, &s2);
        fmi->FreeInstance(fresh.c);
    }
    /* 3. errors, never a crash: a freed state, garbage, a truncated serialization, NULL */
    good &= report(in, "fmi2SetFMUstate back", fmi->SetFMUstate(in->c, s) == fmi2OK);
    fmi2FMUstate tmp = NULL, stale;
    good &= report(in, "fmi2GetFMUstate (second)", fmi->GetFMUstate(in->c, &tmp) == fmi2OK && tmp != NULL);
    stale = tmp;   /* fmi2FreeFMUstate sets *FMUstate = NULL: keep the pointer */
    good &= report(in, "fmi2FreeFMUstate", fmi->FreeFMUstate(in->c, &tmp) == fmi2OK && tmp == NULL);
    good &= report(in, "a freed state is fmi2Error", fmi->SetFMUstate(in->c, stale) == fmi2Error);
    static const char garbage[] = "this is not a serialized FMU state of any model, just bytes";
    fmi2FMUstate g = NULL;
    good &= report(in, "garbage bytes are fmi2Error",
                   fmi->DeSerializeFMUstate(in->c, garbage, sizeof garbage, &g) == fmi2Error && g == NULL);
    good &= report(in, "a truncated serialization is fmi2Error",
                   bytes && n > 8 && fmi->DeSerializeFMUstate(in->c, bytes, n - 8, &g) == fmi2Error && g == NULL);
    good &= report(in, "a NULL state is fmi2Error", fmi->SetFMUstate(in->c, NULL) == fmi2Error);
    /* the instance still works: state s set back, then freed */
    good &= report(in, "fmi2SetFMUstate after the errors", fmi->SetFMUstate(in->c, s) == fmi2OK);
    good &= report(in, "fmi2FreeFMUstate (first)", fmi->FreeFMUstate(in->c, &s) == fmi2OK);
    free(bytes);
    return good;
}

int main(int argc, char** argv) {
    static Fmu fmus[MAX_FMU];
    static Instance inst[MAX_INST];
    size_t n_fmu = 0, n_inst = 0, n_out = 0;
    fmi2ValueReference out[MAX_VARS];
    double h = 0.0, stop = 0.0, t0 = 0.0;
    const char* unload = "reverse";
    Values* target = NULL;

    if (argc < 2) usage("no FMU directory");
    fmus[n_fmu++].arg = argv[1];
    for (int i = 2; i < argc; ++i) {
        const char* a = argv[i];
        Instance* in = n_inst ? &inst[n_inst - 1] : NULL;
        int more = i + 1 < argc;
        if (!strcmp(a, "--step") && more) h = number(argv[++i]);
        else if (!strcmp(a, "--stop") && more) stop = number(argv[++i]);
        else if (!strcmp(a, "--unload") && more) unload = argv[++i];
        else if (!strcmp(a, "--fmu") && more) {
            if (n_fmu == MAX_FMU) usage("too many FMUs");
            fmus[n_fmu++].arg = argv[++i];
            target = NULL;
        } else if (!strcmp(a, "--output") && more) {
            n_out = 0;
            for (char* tok = strtok(argv[++i], ","); tok; tok = strtok(NULL, ",")) {
                if (n_out == MAX_VARS) usage("too many outputs");
                out[n_out++] = (fmi2ValueReference)number(tok);
            }
        } else if (!strcmp(a, "--instance") && more) {
            if (n_inst == MAX_INST) usage("too many instances");
            Instance* ni = &inst[n_inst++];
            ni->name = argv[++i];
            ni->fmu = &fmus[n_fmu - 1];
            ni->n_out = n_out;
            memcpy(ni->out, out, sizeof out);
            ni->state_check = -1;
            target = &ni->params;
        } else if (!in || !target) usage("--instance NAME must come before instance options");
        else if (!strcmp(a, "--input") && more) {
            Values v = {0};
            add_value(&v, argv[++i]);
            in->has_input = 1;
            in->input_vr = v.vr[0];
            in->V0 = v.value[0];
        } else if (!strcmp(a, "--sine") && more) in->freq = number(argv[++i]);
        else if (!strcmp(a, "--state-check") && more) in->state_check = lround(number(argv[++i]));
        else if (!strcmp(a, "--reset")) {
            in->has_reset = 1;
            target = &in->reset_params;
        } else add_value(target, a);
    }
    if (!(h > 0.0) || !(stop > t0) || !n_inst) usage("need --step > 0, --stop > 0, a RUN");
    for (size_t i = 0; i < n_inst; ++i)
        if (!inst[i].n_out) usage("every RUN needs an --output list before it");
    if (strcmp(unload, "reverse") && strcmp(unload, "forward") && strcmp(unload, "none")) usage("bad --unload");
    long n_steps = lround((stop - t0) / h);

    /* load every FMU (in the order given), then instantiate (in the order given) and initialize */
    for (size_t k = 0; k < n_fmu; ++k) {
        int rc = load_fmu(&fmus[k]);
        if (rc) return rc;
    }
    fmi2Status st = fmi2OK;
    int rc = 0;
    size_t n_live = 0;
    for (; n_live < n_inst; ++n_live) {
        Instance* in = &inst[n_live];
        in->c = in->fmu->fmi.Instantiate(in->name, fmi2CoSimulation, in->fmu->guid, in->fmu->resources,
                                         &callbacks, 0, 0);
        if (!in->c) { fprintf(stderr, "fmi2_cs_host: fmi2Instantiate(%s) failed\n", in->name); rc = 3; goto done; }
    }
    for (size_t i = 0; i < n_inst; ++i) {
        Instance* in = &inst[i];
        st = initialize(in, &in->params, t0, stop);
        if (st == fmi2Error && in->has_reset) {   /* e.g. an invalid parameter: start over */
            if (!ok(st = in->fmu->fmi.Reset(in->c), "fmi2Reset", in)) goto failed;
            st = initialize(in, &in->reset_params, t0, stop);
        }
        if (st > fmi2Warning) goto failed;
    }

    /* simulate: header, a row at t0 and after every step */
    printf("time");
    for (size_t i = 0; i < n_inst; ++i)
        for (size_t j = 0; j < inst[i].n_out; ++j) printf(",%s:%u", inst[i].name, inst[i].out[j]);
    for (long k = 0;; ++k) {
        double t = t0 + (double)k * h;   /* as fmpy: start + n*interval, step = t_{k+1} - t_k */
        fmi2Real y[MAX_VARS];
        printf("\n%.17g", t);
        for (size_t i = 0; i < n_inst; ++i) {
            if (!ok(st = inst[i].fmu->fmi.GetReal(inst[i].c, inst[i].out, inst[i].n_out, y), "fmi2GetReal",
                    &inst[i])) goto failed;
            for (size_t j = 0; j < inst[i].n_out; ++j) printf(",%.17g", y[j]);
        }
        if (k == n_steps) break;
        double t_next = t0 + (double)(k + 1) * h;
        for (size_t m = 0; m < n_inst; ++m) {
            Instance* in = &inst[k % 2 ? n_inst - 1 - m : m];   /* interleaved, alternating order */
            if (in->state_check == k && !state_check(in, t0, stop, t, t_next)) { rc = 20; goto done; }
            if (!ok(st = set_input(in, t), "fmi2SetReal", in)) goto failed;
            if (!ok(st = in->fmu->fmi.DoStep(in->c, t, t_next - t, 1), "fmi2DoStep", in)) goto failed;
        }
    }
    printf("\n");
    for (size_t i = 0; i < n_inst; ++i)
        if (!ok(st = inst[i].fmu->fmi.Terminate(inst[i].c), "fmi2Terminate", &inst[i])) goto failed;
    goto done;

failed:
    rc = 10 + (int)st;
    if (st == fmi2Fatal) n_live = 0;   /* FMI 2.0: after fmi2Fatal no function may be called */
done:
    fflush(stdout);
    for (size_t i = 0; i < n_live; ++i) inst[i].fmu->fmi.FreeInstance(inst[i].c);
    if (strcmp(unload, "none") != 0) {
        for (size_t k = 0; k < n_fmu; ++k) {
            Fmu* f = &fmus[strcmp(unload, "forward") == 0 ? k : n_fmu - 1 - k];
            if (f->lib) dlclose(f->lib);
        }
    }
    return rc;
}
