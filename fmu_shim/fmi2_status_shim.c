/*
 * fmi2_status_shim.c -- FMI 2.0 co-simulation "status shim" around pythonfmu's binary.
 *
 * Why this exists
 * ---------------
 * pythonfmu 0.7's C++ binary (libpythonfmu-export) reports EVERY Python exception
 * as fmi2Fatal, and it forwards the slave's log messages only when the instance
 * was created with loggingOn = fmi2True.  The FMU's requirement is that bad
 * parameters give fmi2Error with a message naming the parameter, whatever the
 * logging setting, and that the instance can then be reset (fmi2Error, unlike
 * fmi2Fatal, lets the master call fmi2Reset / fmi2FreeInstance).
 *
 * build_fmu.py compiles this file into binaries/<platform>/<modelIdentifier>.so
 * and renames pythonfmu's binary to <modelIdentifier>_pythonfmu.so next to it.
 * Every FMI 2.0 co-simulation function is exported here and forwarded to that
 * inner library: its path is this library's own (dladdr) with "_pythonfmu"
 * before ".so"; it is dlopen'ed (RTLD_NOW | RTLD_LOCAL) once per process at the
 * first fmi2Instantiate and closed when this library is unloaded.  Each
 * instance has its own shim struct and its own inner pythonfmu instance.
 *
 * Convention with the Python slave (fmu_src/mpc_actuator.py)
 * ----------------------------------------------------------
 * A recoverable error is reported by the slave by logging a message at
 * Fmi2Status.error.  Where the FMU lists this platform in
 * resources/status_shim.json (build_fmu.py writes it with the shim) the slave
 * then returns normally: pythonfmu returns fmi2OK (fmi2Discard from a doStep that
 * returned False) and its instance stays intact; the shim, which saw the error
 * message during the call, returns fmi2Error and forwards fmi2Reset and
 * fmi2FreeInstance to that instance.  A slave that logs and then raises gets
 * fmi2Fatal from pythonfmu; the shim still returns fmi2Error for it, but
 * pythonfmu's instance is then broken (below).  A fatal without a preceding
 * error message (an unexpected exception) stays fmi2Fatal.
 *
 * What the shim does
 * ------------------
 * - The inner instance always runs with loggingOn = fmi2True and with a copy of
 *   the host's callbacks whose logger is the shim's.  The shim forwards a
 *   message to the host when the host asked for logging (fmi2Instantiate /
 *   fmi2SetDebugLogging, with its categories), and always when its status is
 *   fmi2Warning or worse.  pythonfmu's generic "Fatal py exception" message that
 *   follows a reported error is not forwarded (the host gets the slave's own
 *   message at fmi2Error).
 * - pythonfmu 0.7 cannot be used again after any Python exception: its handler
 *   releases the Python slave object and class but keeps the dangling pointers,
 *   and its destructor releases them a second time (use after free; a
 *   PYTHONMALLOC=debug host crashes).  So after an inner fmi2Fatal the shim never
 *   calls that inner instance again, not even fmi2FreeInstance (the small C++
 *   object is leaked and the inner library is never unloaded).  After such an
 *   fmi2Error (logged, then raised), fmi2Reset instantiates a fresh inner
 *   instance (start values, as fmi2Reset requires); fmi2FreeInstance only frees
 *   the shim's part.  Other calls in that state return fmi2Error (fmi2Fatal in
 *   the fatal state) with a message.
 *
 * Only this platform's binary is wrapped; the other platforms' binaries in the
 * FMU stay pythonfmu's stock ones (fmi2Fatal for every Python exception).
 * POSIX/ELF only (dlopen, dladdr).  Build (build_fmu.py): cc -shared -fPIC -O2
 * -Wall -Wextra -pthread -fvisibility=hidden -o <id>.so fmi2_status_shim.c -ldl.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- FMI 2.0 types (as in the standard's fmi2TypesPlatform.h / fmi2FunctionTypes.h) ---- */
typedef void* fmi2Component;
typedef void* fmi2ComponentEnvironment;
typedef void* fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char* fmi2String;
typedef char fmi2Byte;
#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef void* (*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void*);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);

typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#define fmi2TypesPlatform "default"
#define fmi2Version "2.0"

#define SHIM_EXPORT __attribute__((visibility("default")))
/* the inner library: <this library's name without .so> + SHIM_INNER_SUFFIX, same folder */
#define SHIM_INNER_SUFFIX "_pythonfmu.so"

/* ---- the inner library's functions ---- */
typedef struct {
    fmi2Component (*Instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions*,
                                 fmi2Boolean, fmi2Boolean);
    void (*FreeInstance)(fmi2Component);
    fmi2Status (*SetupExperiment)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
    fmi2Status (*EnterInitializationMode)(fmi2Component);
    fmi2Status (*ExitInitializationMode)(fmi2Component);
    fmi2Status (*Terminate)(fmi2Component);
    fmi2Status (*Reset)(fmi2Component);
    fmi2Status (*GetReal)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Real[]);
    fmi2Status (*GetInteger)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Integer[]);
    fmi2Status (*GetBoolean)(fmi2Component, const fmi2ValueReference[], size_t, fmi2Boolean[]);
    fmi2Status (*GetString)(fmi2Component, const fmi2ValueReference[], size_t, fmi2String[]);
    fmi2Status (*SetReal)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Real[]);
    fmi2Status (*SetInteger)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[]);
    fmi2Status (*SetBoolean)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Boolean[]);
    fmi2Status (*SetString)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2String[]);
    fmi2Status (*GetFMUstate)(fmi2Component, fmi2FMUstate*);
    fmi2Status (*SetFMUstate)(fmi2Component, fmi2FMUstate);
    fmi2Status (*FreeFMUstate)(fmi2Component, fmi2FMUstate*);
    fmi2Status (*SerializedFMUstateSize)(fmi2Component, fmi2FMUstate, size_t*);
    fmi2Status (*SerializeFMUstate)(fmi2Component, fmi2FMUstate, fmi2Byte[], size_t);
    fmi2Status (*DeSerializeFMUstate)(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate*);
    fmi2Status (*GetDirectionalDerivative)(fmi2Component, const fmi2ValueReference[], size_t,
                                           const fmi2ValueReference[], size_t, const fmi2Real[], fmi2Real[]);
    fmi2Status (*SetRealInputDerivatives)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                          const fmi2Real[]);
    fmi2Status (*GetRealOutputDerivatives)(fmi2Component, const fmi2ValueReference[], size_t, const fmi2Integer[],
                                           fmi2Real[]);
    fmi2Status (*DoStep)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
    fmi2Status (*CancelStep)(fmi2Component);
    fmi2Status (*GetStatus)(fmi2Component, const fmi2StatusKind, fmi2Status*);
    fmi2Status (*GetRealStatus)(fmi2Component, const fmi2StatusKind, fmi2Real*);
    fmi2Status (*GetIntegerStatus)(fmi2Component, const fmi2StatusKind, fmi2Integer*);
    fmi2Status (*GetBooleanStatus)(fmi2Component, const fmi2StatusKind, fmi2Boolean*);
    fmi2Status (*GetStringStatus)(fmi2Component, const fmi2StatusKind, fmi2String*);
} InnerApi;

/* slot in InnerApi, exported name */
static const struct { size_t offset; const char* name; } INNER_SYMBOLS[] = {
#define SYM(f) {offsetof(InnerApi, f), "fmi2" #f}
    SYM(Instantiate), SYM(FreeInstance), SYM(SetupExperiment), SYM(EnterInitializationMode),
    SYM(ExitInitializationMode), SYM(Terminate), SYM(Reset), SYM(GetReal), SYM(GetInteger), SYM(GetBoolean),
    SYM(GetString), SYM(SetReal), SYM(SetInteger), SYM(SetBoolean), SYM(SetString), SYM(GetFMUstate),
    SYM(SetFMUstate), SYM(FreeFMUstate), SYM(SerializedFMUstateSize), SYM(SerializeFMUstate),
    SYM(DeSerializeFMUstate), SYM(GetDirectionalDerivative), SYM(SetRealInputDerivatives),
    SYM(GetRealOutputDerivatives), SYM(DoStep), SYM(CancelStep), SYM(GetStatus), SYM(GetRealStatus),
    SYM(GetIntegerStatus), SYM(GetBooleanStatus), SYM(GetStringStatus),
#undef SYM
};

typedef enum {
    SHIM_OK,     /* inner instance usable */
    SHIM_ERROR,  /* returned fmi2Error after a reported error: inner abandoned; fmi2Reset re-instantiates */
    SHIM_FATAL   /* returned fmi2Fatal: inner abandoned; only fmi2FreeInstance is meaningful */
} ShimState;

/* one instance: nothing is shared between instances */
typedef struct {
    fmi2CallbackFunctions host;      /* the host's callbacks (copy) */
    fmi2CallbackFunctions inner_cb;  /* given to the inner instance: shim logger, env = this struct */
    const InnerApi* api;
    fmi2Component inner;
    ShimState state;
    int host_logging;                /* the host's loggingOn */
    size_t n_categories;             /* the host's categories (0: all) */
    char** categories;
    int error_logged;                /* the inner logged at fmi2Error during the current call */
    /* fmi2Instantiate's arguments, for re-instantiation in fmi2Reset after an error */
    char* instance_name;
    char* guid;
    char* resource_location;
    fmi2Type fmu_type;
    fmi2Boolean visible;
} Shim;

/* ---- memory: the host's allocator when it gives both functions ---- */
static int host_memory(const fmi2CallbackFunctions* cb) { return cb && cb->allocateMemory && cb->freeMemory; }

static void* shim_calloc(const fmi2CallbackFunctions* cb, size_t n, size_t size) {
    return host_memory(cb) ? cb->allocateMemory(n, size) : calloc(n, size);
}

static void shim_free(const fmi2CallbackFunctions* cb, void* p) {
    if (!p) return;
    if (host_memory(cb)) cb->freeMemory(p); else free(p);
}

static char* shim_strdup(const fmi2CallbackFunctions* cb, const char* s) {
    size_t n = strlen(s ? s : "") + 1;
    char* d = (char*)shim_calloc(cb, n, 1);
    if (d) memcpy(d, s ? s : "", n);
    return d;
}

static void free_categories(Shim* s) {
    for (size_t i = 0; i < s->n_categories; ++i) shim_free(&s->host, s->categories[i]);
    shim_free(&s->host, s->categories);
    s->categories = NULL;
    s->n_categories = 0;
}

/* ---- logging ---- */
static int category_enabled(const Shim* s, fmi2String category) {
    if (s->n_categories == 0) return 1;
    for (size_t i = 0; i < s->n_categories; ++i) {
        if (strcmp(s->categories[i], "logAll") == 0 || (category && strcmp(s->categories[i], category) == 0)) return 1;
    }
    return 0;
}

/* Forward `text` (literal text, not a format) to the host's logger. The logger's message is a printf
 * format, so every '%' is doubled and no arguments are passed. */
static void host_log(Shim* s, fmi2String instance_name, fmi2Status status, fmi2String category, const char* text) {
    if (!s->host.logger) return;
    if (status < fmi2Warning && !(s->host_logging && category_enabled(s, category))) return;
    if (!text) text = "";
    size_t n = strlen(text), pct = 0;
    for (size_t i = 0; i < n; ++i) pct += (text[i] == '%');
    char small[512];
    char* buf = (n + pct + 1 <= sizeof small) ? small : (char*)malloc(n + pct + 1);
    if (!buf) return;
    char* o = buf;
    for (size_t i = 0; i < n; ++i) {
        *o++ = text[i];
        if (text[i] == '%') *o++ = '%';
    }
    *o = '\0';
    s->host.logger(s->host.componentEnvironment, instance_name ? instance_name : s->instance_name, status,
                   category, buf);
    if (buf != small) free(buf);
}

static void shim_message(Shim* s, fmi2Status status, const char* fmt, ...) __attribute__((format(printf, 3, 4)));
static void shim_message(Shim* s, fmi2Status status, const char* fmt, ...) {
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    host_log(s, NULL, status, status >= fmi2Fatal ? "logStatusFatal" : status >= fmi2Error ? "logStatusError"
             : status >= fmi2Warning ? "logStatusWarning" : "logAll", text);
}

/* The inner instance's logger. pythonfmu passes the message as literal text and no arguments. */
static void shim_logger(fmi2ComponentEnvironment env, fmi2String instance_name, fmi2Status status,
                        fmi2String category, fmi2String message, ...) {
    Shim* s = (Shim*)env;
    if (!s) return;
    if (status == fmi2Fatal && s->error_logged) {
        /* pythonfmu's generic "Fatal py exception" after the slave reported the error itself: the call will
         * return fmi2Error and the host already has the slave's message */
        return;
    }
    if (status == fmi2Error) s->error_logged = 1;
    host_log(s, instance_name, status, category, message);
}

static void shim_step_finished(fmi2ComponentEnvironment env, fmi2Status status) {
    Shim* s = (Shim*)env;
    if (s && s->host.stepFinished) s->host.stepFinished(s->host.componentEnvironment, status);
}

/* ---- the inner library ----
 * Loaded once per process (at the first fmi2Instantiate) and closed when the shim itself is unloaded, so
 * the embedded Python lives as long as with the stock binary (pythonfmu finalizes Python, when it started
 * it, only when its library is unloaded; numpy cannot be imported again after that). */
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static void* g_handle;   /* dlopen handle of the inner library */
static InnerApi g_api;
static int g_abandoned;  /* an inner instance was abandoned (see abandon_inner): never unload */
static int g_started_python = -1;  /* -1 unknown; 1: Python was not running before the first instantiate */
static int g_exit_registered;     /* finalize_inner_python registered with atexit */
static void (*g_finalize)(void);   /* the inner library's finalizePythonInterpreter, or NULL */

static const InnerApi* load_inner(Shim* s) {
    pthread_mutex_lock(&g_lock);
    if (g_handle) {
        pthread_mutex_unlock(&g_lock);
        return &g_api;
    }
    const InnerApi* result = NULL;
    char* path = NULL;
    Dl_info info;
    if (!dladdr((const void*)&g_lock, &info) || !info.dli_fname) {  /* any object of this library */
        shim_message(s, fmi2Fatal, "fmi2Instantiate: the status shim cannot find its own file (dladdr failed)");
        goto out;
    }
    size_t len = strlen(info.dli_fname);
    if (len > 3 && strcmp(info.dli_fname + len - 3, ".so") == 0) len -= 3;
    path = (char*)malloc(len + sizeof SHIM_INNER_SUFFIX);
    if (!path) goto out;
    memcpy(path, info.dli_fname, len);
    memcpy(path + len, SHIM_INNER_SUFFIX, sizeof SHIM_INNER_SUFFIX);
    if (g_started_python < 0) {  /* is an interpreter running already (Python host)? */
        void* sym = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
        int (*is_init)(void) = NULL;
        if (sym) memcpy(&is_init, &sym, sizeof is_init);
        g_started_python = !(is_init && is_init());
    }
    void* handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
        const char* why = dlerror();
        shim_message(s, fmi2Fatal, "fmi2Instantiate: the status shim cannot load %s: %s", path, why ? why : "?");
        goto out;
    }
    InnerApi api;
    for (size_t i = 0; i < sizeof INNER_SYMBOLS / sizeof INNER_SYMBOLS[0]; ++i) {
        void* f = dlsym(handle, INNER_SYMBOLS[i].name);
        if (!f) {
            shim_message(s, fmi2Fatal, "fmi2Instantiate: %s does not export %s", path, INNER_SYMBOLS[i].name);
            dlclose(handle);
            goto out;
        }
        memcpy((char*)&api + INNER_SYMBOLS[i].offset, &f, sizeof f);  /* object -> function pointer (POSIX) */
    }
    g_api = api;
    g_handle = handle;
    {
        void* fin = dlsym(handle, "finalizePythonInterpreter");  /* pythonfmu's; see finalize_inner_python */
        if (fin) memcpy(&g_finalize, &fin, sizeof fin);          /* object -> function pointer (POSIX) */
    }
    result = &g_api;
out:
    pthread_mutex_unlock(&g_lock);
    free(path);
    return result;
}

/* ---- pythonfmu's interpreter state at exit and unload ----
 * pythonfmu keeps its interpreter state in a static std::shared_ptr whose destructor runs among the exit
 * handlers, and its library destructor (onLibraryUnload, from _dl_fini, i.e. later) then assigns nullptr to
 * that destroyed shared_ptr: the control block is released a second time (a use after free; seen with gdb:
 * ~shared_ptr<PyState> from __run_exit_handlers, then finalizePythonInterpreter from _dl_fini). In any host
 * this corrupts the heap at exit; glibc notices now and then ("corrupted double-linked list", about 1 in 400
 * short fmpy runs here). Calling pythonfmu's exported finalizePythonInterpreter() first, while the
 * shared_ptr is alive, empties it, and both later calls do nothing. The shim does that from an atexit handler
 * registered after the inner library is loaded (atexit handlers run in the reverse order of registration:
 * before the inner library's static destructors) and from its own destructor before closing the inner
 * library (a host that unloads the FMU; the handler also runs then, atexit being bound to this library).
 * In a host without Python (C, Modelica or Simulink style tools, LD_PRELOAD=libpython) pythonfmu started
 * the interpreter and this call also finalizes it (when no live instance holds the state), which must happen
 * before the C++ static destructors of SciPy's and numba's extension modules (imported on instantiation,
 * before the handler is registered): otherwise Py_Finalize touches freed memory and the host segfaults at
 * exit (8 of 10 runs; tests/fmu/test_c_host.py). There the shim pins itself (RTLD_NODELETE) so that this happens
 * at exit, not when a host unloads the FMU (numpy cannot be imported again into a re-started interpreter).
 * In a Python host (fmpy) Python was running before the first fmi2Instantiate: the call only drops
 * pythonfmu's reference. */

static void finalize_inner_python(void) {
    pthread_mutex_lock(&g_lock);
    void (*fin)(void) = g_finalize;
    pthread_mutex_unlock(&g_lock);
    if (fin) fin();
}

static void register_exit_finalization(void) {
    pthread_mutex_lock(&g_lock);
    if (!g_exit_registered && g_handle) {
        if (g_started_python == 1) {
            Dl_info info;
            if (dladdr((const void*)&g_lock, &info) && info.dli_fname)
                (void)dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);  /* pin this library */
        }
        g_exit_registered = (atexit(finalize_inner_python) == 0);
    }
    pthread_mutex_unlock(&g_lock);
}

__attribute__((destructor)) static void unload_inner(void) {
    finalize_inner_python();
    pthread_mutex_lock(&g_lock);
    if (g_handle && !g_abandoned) dlclose(g_handle);
    g_handle = NULL;
    g_finalize = NULL;
    pthread_mutex_unlock(&g_lock);
}

/* Instantiate the inner FMU (always with logging on). */
static int instantiate_inner(Shim* s) {
    s->api = load_inner(s);
    if (!s->api) return 0;
    s->error_logged = 0;
    s->inner = s->api->Instantiate(s->instance_name, s->fmu_type, s->guid, s->resource_location, &s->inner_cb,
                                   s->visible, fmi2True);
    if (!s->inner) return 0;
    s->state = SHIM_OK;
    register_exit_finalization();  /* once, after the slave's imports; also for hosts that never free */
    return 1;
}

/* The inner instance is not usable after fmi2Fatal (see the header): never call it again, not even
 * fmi2FreeInstance (a small C++ object is leaked), and keep its library loaded. */
static void abandon_inner(Shim* s, ShimState state) {
    s->inner = NULL;
    s->state = state;
    pthread_mutex_lock(&g_lock);
    g_abandoned = 1;
    pthread_mutex_unlock(&g_lock);
}

/* Before a forwarded call: OK if the inner instance may be called, else the status to return. */
static fmi2Status shim_enter(Shim* s, const char* fn) {
    if (s->state == SHIM_OK) {
        s->error_logged = 0;
        return fmi2OK;
    }
    if (s->state == SHIM_ERROR) {
        shim_message(s, fmi2Error, "%s: not possible after an error (see the earlier message); call fmi2Reset "
                     "or fmi2FreeInstance", fn);
        return fmi2Error;
    }
    shim_message(s, fmi2Fatal, "%s: not possible after fmi2Fatal; only fmi2FreeInstance is allowed", fn);
    return fmi2Fatal;
}

/* After a forwarded call: the slave's reported errors become fmi2Error. With this shim the slave reports a
 * recoverable error by logging it at fmi2Error and returning normally (pythonfmu then returns fmi2OK, or
 * fmi2Discard from a doStep that returned False): the inner instance stays intact and fmi2Reset is forwarded
 * to it. A slave that logs and then raises gets fmi2Fatal from pythonfmu, whose instance is then broken: it
 * is abandoned (below). */
static fmi2Status shim_leave(Shim* s, fmi2Status status) {
    if (status != fmi2Fatal) return (s->error_logged && status < fmi2Error) ? fmi2Error : status;
    if (s->error_logged) {
        abandon_inner(s, SHIM_ERROR);
        return fmi2Error;
    }
    abandon_inner(s, SHIM_FATAL);
    return fmi2Fatal;
}

#define FORWARD(fn, ...)                                              \
    do {                                                              \
        Shim* s_ = (Shim*)c;                                          \
        if (!s_) return fmi2Error;                                    \
        fmi2Status st_ = shim_enter(s_, "fmi2" #fn);                  \
        if (st_ != fmi2OK) return st_;                                \
        return shim_leave(s_, s_->api->fn(s_->inner, __VA_ARGS__));    \
    } while (0)

#define FORWARD0(fn)                                                  \
    do {                                                              \
        Shim* s_ = (Shim*)c;                                          \
        if (!s_) return fmi2Error;                                    \
        fmi2Status st_ = shim_enter(s_, "fmi2" #fn);                  \
        if (st_ != fmi2OK) return st_;                                \
        return shim_leave(s_, s_->api->fn(s_->inner));                 \
    } while (0)

/* ======================================================================================== */
/* exported FMI 2.0 co-simulation functions                                                 */
/* ======================================================================================== */
SHIM_EXPORT const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

SHIM_EXPORT const char* fmi2GetVersion(void) { return fmi2Version; }

SHIM_EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                          fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                          fmi2Boolean visible, fmi2Boolean loggingOn) {
    if (!functions) return NULL;
    Shim* s = (Shim*)shim_calloc(functions, 1, sizeof(Shim));
    if (!s) return NULL;
    memcpy(&s->host, functions, sizeof s->host);
    const fmi2CallbackFunctions inner_cb = {shim_logger, functions->allocateMemory, functions->freeMemory,
                                            shim_step_finished, s};
    memcpy(&s->inner_cb, &inner_cb, sizeof inner_cb);
    s->host_logging = (loggingOn == fmi2True);
    s->fmu_type = fmuType;
    s->visible = visible;
    s->instance_name = shim_strdup(functions, instanceName);
    s->guid = shim_strdup(functions, fmuGUID);
    s->resource_location = shim_strdup(functions, fmuResourceLocation);
    if (s->instance_name && s->guid && s->resource_location && instantiate_inner(s)) return s;
    shim_free(functions, s->instance_name);
    shim_free(functions, s->guid);
    shim_free(functions, s->resource_location);
    shim_free(functions, s);
    return NULL;
}

SHIM_EXPORT void fmi2FreeInstance(fmi2Component c) {
    Shim* s = (Shim*)c;
    if (!s) return;
    if (s->state == SHIM_OK && s->inner) s->api->FreeInstance(s->inner);
    fmi2CallbackFunctions host;
    memcpy(&host, &s->host, sizeof host);
    free_categories(s);
    shim_free(&host, s->instance_name);
    shim_free(&host, s->guid);
    shim_free(&host, s->resource_location);
    shim_free(&host, s);
}

SHIM_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                           const fmi2String categories[]) {
    /* recorded here; the inner instance keeps logging everything to the shim */
    Shim* s = (Shim*)c;
    if (!s) return fmi2Error;
    free_categories(s);
    s->host_logging = (loggingOn == fmi2True);
    if (nCategories > 0 && categories) {
        s->categories = (char**)shim_calloc(&s->host, nCategories, sizeof(char*));
        if (!s->categories) return fmi2Error;
        for (size_t i = 0; i < nCategories; ++i) {
            s->categories[i] = shim_strdup(&s->host, categories[i]);
            if (!s->categories[i]) {
                s->n_categories = i;
                return fmi2Error;
            }
        }
        s->n_categories = nCategories;
    }
    return fmi2OK;
}

SHIM_EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                           fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    FORWARD(SetupExperiment, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
}

SHIM_EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) { FORWARD0(EnterInitializationMode); }

SHIM_EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) { FORWARD0(ExitInitializationMode); }

SHIM_EXPORT fmi2Status fmi2Terminate(fmi2Component c) { FORWARD0(Terminate); }

SHIM_EXPORT fmi2Status fmi2Reset(fmi2Component c) {
    Shim* s = (Shim*)c;
    if (!s) return fmi2Error;
    if (s->state == SHIM_ERROR) {
        /* the old inner instance is abandoned: a fresh one has the start values */
        if (instantiate_inner(s)) return fmi2OK;
        shim_message(s, fmi2Error, "fmi2Reset: re-instantiating the model failed");
        return fmi2Error;
    }
    FORWARD0(Reset);
}

SHIM_EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    FORWARD(GetReal, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Integer value[]) {
    FORWARD(GetInteger, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Boolean value[]) {
    FORWARD(GetBoolean, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     fmi2String value[]) {
    FORWARD(GetString, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                   const fmi2Real value[]) {
    FORWARD(SetReal, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Integer value[]) {
    FORWARD(SetInteger, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Boolean value[]) {
    FORWARD(SetBoolean, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     const fmi2String value[]) {
    FORWARD(SetString, vr, nvr, value);
}

SHIM_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) { FORWARD(GetFMUstate, FMUstate); }

SHIM_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) { FORWARD(SetFMUstate, FMUstate); }

SHIM_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) {
    FORWARD(FreeFMUstate, FMUstate);
}

SHIM_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t* size) {
    FORWARD(SerializedFMUstateSize, FMUstate, size);
}

SHIM_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                             size_t size) {
    FORWARD(SerializeFMUstate, FMUstate, serializedState, size);
}

SHIM_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate* FMUstate) {
    FORWARD(DeSerializeFMUstate, serializedState, size, FMUstate);
}

SHIM_EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                                    size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                                    size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    FORWARD(GetDirectionalDerivative, vUnknown_ref, nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown);
}

SHIM_EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[], const fmi2Real value[]) {
    FORWARD(SetRealInputDerivatives, vr, nvr, order, value);
}

SHIM_EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                    const fmi2Integer order[], fmi2Real value[]) {
    FORWARD(GetRealOutputDerivatives, vr, nvr, order, value);
}

SHIM_EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                                  fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    FORWARD(DoStep, currentCommunicationPoint, communicationStepSize, noSetFMUStatePriorToCurrentPoint);
}

SHIM_EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { FORWARD0(CancelStep); }

SHIM_EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* value) {
    FORWARD(GetStatus, s, value);
}

SHIM_EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value) {
    FORWARD(GetRealStatus, s, value);
}

SHIM_EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* value) {
    FORWARD(GetIntegerStatus, s, value);
}

SHIM_EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value) {
    FORWARD(GetBooleanStatus, s, value);
}

SHIM_EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* value) {
    FORWARD(GetStringStatus, s, value);
}
