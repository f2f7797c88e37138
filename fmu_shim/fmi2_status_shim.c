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
 * first fmi2Instantiate, after the shim made sure Python can start (see "finding
 * Python"); the shim then pins itself until exit (see "the embedded interpreter at
 * exit").  Each instance has its own shim struct and its own inner pythonfmu
 * instance.  FMU states are the shim's own objects (see "FMU state save/restore"),
 * and every message to the host's logger is sanitized (no NULL, bounded length).
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
#include <link.h>
#include <pthread.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
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

/* Categories of the standard, one per status (a NULL or empty category from the inner library becomes one
 * of these: a C++ host builds std::string from it and aborts on NULL). */
static const char* status_category(fmi2Status status) {
    return status >= fmi2Fatal ? "logStatusFatal" : status >= fmi2Error ? "logStatusError"
           : status == fmi2Discard ? "logStatusDiscard" : status >= fmi2Warning ? "logStatusWarning" : "logAll";
}

/* Longest message text passed to the host's logger, in bytes without the terminating NUL (after '%' doubling).
 * Longer messages are cut at a UTF-8 character boundary and end with SHIM_TRUNCATED. */
#define SHIM_MAX_MESSAGE 4000
#define SHIM_TRUNCATED " [... message truncated by the FMU]"

/* Forward `text` (literal text, not a format) to the host's logger. Nothing the host gets is NULL: a NULL
 * instance name becomes this instance's name (or the model identifier), a NULL or empty category the
 * standard category of the status, a NULL message "". The logger's message is a printf format, so every '%'
 * is doubled and no arguments are passed; the text is cut to SHIM_MAX_MESSAGE bytes (a fixed buffer: no
 * allocation while logging). */
static void host_log(Shim* s, fmi2String instance_name, fmi2Status status, fmi2String category, const char* text) {
    if (!s->host.logger) return;
    if (status < fmi2Warning && !(s->host_logging && category_enabled(s, category))) return;
    if (!text) text = "";
    if (!category || !*category) category = status_category(status);
    if (!instance_name) instance_name = s->instance_name ? s->instance_name : "mpc_actuator";
    char buf[SHIM_MAX_MESSAGE + sizeof SHIM_TRUNCATED];
    const size_t limit = SHIM_MAX_MESSAGE;
    size_t o = 0, i = 0;
    for (; text[i]; ++i) {
        size_t need = (text[i] == '%') ? 2 : 1;
        if (o + need > limit) break;
        buf[o++] = text[i];
        if (text[i] == '%') buf[o++] = '%';
    }
    if (text[i]) {   /* cut: back to the start of a UTF-8 character, then the marker */
        /* text[i] is the first byte not written; while it continues a multi-byte character, drop that
         * character's bytes already written (they are never '%', so buf and text step back together) */
        while (o > 0 && i > 0 && (((unsigned char)text[i]) & 0xC0) == 0x80) { --o; --i; }
        memcpy(buf + o, SHIM_TRUNCATED, sizeof SHIM_TRUNCATED);
    } else {
        buf[o] = '\0';
    }
    s->host.logger(s->host.componentEnvironment, instance_name, status, category, buf);
}

static void shim_message(Shim* s, fmi2Status status, const char* fmt, ...) __attribute__((format(printf, 3, 4)));
static void shim_message(Shim* s, fmi2Status status, const char* fmt, ...) {
    char text[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    host_log(s, NULL, status, status_category(status), text);
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
 * Loaded once per process (at the first fmi2Instantiate) and never unloaded before exit: the shim pins itself
 * (see "exit" below), and pythonfmu's library cannot be unloaded anyway (libstdc++ unique symbols). */
static pthread_mutex_t g_lock = PTHREAD_MUTEX_INITIALIZER;
static void* g_handle;   /* dlopen handle of the inner library */
static InnerApi g_api;
static int g_abandoned;  /* an inner instance was abandoned (see abandon_inner): never unload */
static int g_exit_registrations;   /* finalize_pythonfmu_at_exit registered with atexit (once per instantiate) */
static void (*g_finalize)(void);   /* the inner library's finalizePythonInterpreter, or NULL */

/* ---- finding Python (item "no set-up on a prepared machine") ----
 * pythonfmu's binary does not link libpython and starts the interpreter with a bare Py_Initialize(), which
 * takes its home and module path from PYTHONHOME / PYTHONPATH (else from the first python3 on PATH). Before
 * the inner library is loaded the shim makes sure of both, but only when no interpreter runs in the process
 * yet (a Python host, or another FMU that started one, is never touched):
 *   - the interpreter to use: the JSON file named by the environment variable MPC_ACTUATOR_PYTHON, else
 *     resources/python.json (build_fmu.py records the building interpreter there):
 *       {"format": "mpc_actuator-python/1", "version": "3.11", "libpython": ".../libpython3.11.so",
 *        "home": "<sys.base_prefix>", "paths": ["<venv site-packages>", ...]}
 *   - libpython is loaded with RTLD_GLOBAL when the process has none (an LD_PRELOAD'ed one is used as is);
 *   - PYTHONHOME = home and PYTHONPATH = paths are set for the duration of the first inner fmi2Instantiate
 *     (when pythonfmu starts the interpreter), each only when the host's environment does not set it, and
 *     removed again afterwards.
 * Without a usable configuration fmi2Instantiate logs what is missing and how to provide it, and returns
 * NULL. */
#define SHIM_PYTHON_ENV "MPC_ACTUATOR_PYTHON"
#define SHIM_PYTHON_JSON "python.json"
#define SHIM_MAX_CONFIG (64 * 1024)
static int g_env_set_home, g_env_set_path;   /* PYTHONHOME / PYTHONPATH set by the shim (to be removed) */
static char g_python_source[4400];           /* where the interpreter came from (for messages) */

/* the value of "key" in a flat JSON object: a string (array = 0) or an array of strings joined with ':'
 * (array = 1); returns 1 on success. Escapes \" \\ \/ only (paths). */
static int json_value(const char* json, const char* key, int array, char* out, size_t n) {
    char pat[64];
    snprintf(pat, sizeof pat, "\"%s\"", key);
    const char* p = strstr(json, pat);
    if (!p) return 0;
    p += strlen(pat);
    while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r') ++p;
    if (*p++ != ':') return 0;
    while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r') ++p;
    if (array && *p++ != '[') return 0;
    size_t o = 0;
    for (int first = 1;; first = 0) {
        while (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r' || (array && !first && *p == ',')) ++p;
        if (array && *p == ']') break;
        if (*p++ != '"') return 0;
        if (array && !first) {
            if (o + 1 >= n) return 0;
            out[o++] = ':';
        }
        for (; *p && *p != '"'; ++p) {
            char c = *p;
            if (c == '\\') {
                c = *++p;
                if (c != '"' && c != '\\' && c != '/') return 0;
            }
            if (o + 1 >= n) return 0;
            out[o++] = c;
        }
        if (*p++ != '"') return 0;
        if (!array) break;
    }
    out[o] = '\0';
    return 1;
}

/* resources folder (a file: URI) -> path; returns 1 on success */
static int uri_to_path(const char* uri, char* out, size_t n) {
    if (!uri) return 0;
    if (strncmp(uri, "file://localhost/", 17) == 0) uri += 16;
    else if (strncmp(uri, "file:///", 8) == 0) uri += 7;
    else if (strncmp(uri, "file:/", 6) == 0) uri += 5;
    else if (uri[0] != '/') return 0;
    size_t o = 0;
    for (; *uri; ++uri) {
        char c = *uri;
        if (c == '%' && uri[1] && uri[2]) {
            char hex[3] = {uri[1], uri[2], 0};
            c = (char)strtol(hex, NULL, 16);
            uri += 2;
        }
        if (o + 1 >= n) return 0;
        out[o++] = c;
    }
    while (o > 1 && out[o - 1] == '/') --o;
    out[o] = '\0';
    return 1;
}

static char* read_small_file(const char* path) {
    FILE* f = fopen(path, "rb");
    if (!f) return NULL;
    char* buf = (char*)malloc(SHIM_MAX_CONFIG + 1);
    size_t n = buf ? fread(buf, 1, SHIM_MAX_CONFIG, f) : 0;
    fclose(f);
    if (buf) buf[n] = '\0';
    return buf;
}

static int python_running(void) {
    void* sym = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    int (*is_init)(void) = NULL;
    if (sym) memcpy(&is_init, &sym, sizeof is_init);   /* object -> function pointer (POSIX) */
    return is_init && is_init();
}

/* Called with g_lock held before the inner library is loaded; returns 1 to go on, 0 after logging why not. */
static int prepare_python(Shim* s) {
    if (python_running()) {   /* a Python host, or another FMU started it: never touch it */
        snprintf(g_python_source, sizeof g_python_source, "the Python already running in this process");
        return 1;
    }
    const int have_lib = dlsym(RTLD_DEFAULT, "Py_IsInitialized") != NULL;   /* e.g. LD_PRELOAD */
    const char* env = getenv(SHIM_PYTHON_ENV);
    char path[4200], resources[4096];
    if (env && *env) {
        snprintf(path, sizeof path, "%s", env);
        snprintf(g_python_source, sizeof g_python_source, "%s=%s", SHIM_PYTHON_ENV, env);
    } else if (uri_to_path(s->resource_location, resources, sizeof resources)) {
        snprintf(path, sizeof path, "%s/%s", resources, SHIM_PYTHON_JSON);
        snprintf(g_python_source, sizeof g_python_source, "%s", path);
    } else {
        path[0] = '\0';
        snprintf(g_python_source, sizeof g_python_source, "(no resources folder: fmuResourceLocation %s)",
                 s->resource_location ? s->resource_location : "NULL");
    }
    char* json = path[0] ? read_small_file(path) : NULL;
    if (!json) {
        if (have_lib && !(env && *env)) {   /* the host's own set-up (LD_PRELOAD, PYTHONHOME, PYTHONPATH) */
            snprintf(g_python_source, sizeof g_python_source, "the libpython loaded by the host (LD_PRELOAD)");
            return 1;
        }
        shim_message(s, fmi2Error,
                     "fmi2Instantiate: this FMU runs embedded Python 3.11 with numpy, scipy and numba, and no Python "
                     "is configured: %s cannot be read%s. Either set the environment variable %s to a JSON file "
                     "{\"libpython\": \".../libpython3.11.so\", \"home\": \"<sys.base_prefix>\", \"paths\": "
                     "[\"<site-packages with numpy, scipy, numba>\"]}, or rebuild the FMU on this machine "
                     "(`make fmu` records the interpreter in resources/%s), or start the host with "
                     "LD_PRELOAD=<libpython3.11.so> PYTHONHOME=<sys.base_prefix> PYTHONPATH=<site-packages>",
                     path[0] ? path : g_python_source, (env && *env) ? " (named by " SHIM_PYTHON_ENV ")" : "",
                     SHIM_PYTHON_ENV, SHIM_PYTHON_JSON);
        return 0;
    }
    static char lib[4096], home[4096], paths[16384];
    int good = json_value(json, "libpython", 0, lib, sizeof lib) && json_value(json, "home", 0, home, sizeof home)
               && json_value(json, "paths", 1, paths, sizeof paths);
    free(json);
    if (!good) {
        shim_message(s, fmi2Error, "fmi2Instantiate: %s is not a valid Python description: it needs the strings "
                     "\"libpython\" and \"home\" and the list of strings \"paths\" (see README.md, \"Using the FMU "
                     "in a system simulator\")", g_python_source);
        return 0;
    }
    if (!have_lib && !dlopen(lib, RTLD_NOW | RTLD_GLOBAL)) {   /* never closed */
        const char* why = dlerror();
        shim_message(s, fmi2Error, "fmi2Instantiate: cannot load the Python library %s (from %s): %s. Set %s to a "
                     "JSON file describing a Python 3.11 with numpy, scipy and numba on this machine, or rebuild the "
                     "FMU here (`make fmu`)", lib, g_python_source, why ? why : "?", SHIM_PYTHON_ENV);
        return 0;
    }
    if (!getenv("PYTHONHOME")) g_env_set_home = (setenv("PYTHONHOME", home, 1) == 0);
    if (!getenv("PYTHONPATH")) g_env_set_path = (setenv("PYTHONPATH", paths, 1) == 0);
    return 1;
}

/* after the first inner fmi2Instantiate: the interpreter has read its configuration */
static void restore_python_env(void) {
    pthread_mutex_lock(&g_lock);
    if (g_env_set_home) unsetenv("PYTHONHOME");
    if (g_env_set_path) unsetenv("PYTHONPATH");
    g_env_set_home = g_env_set_path = 0;
    pthread_mutex_unlock(&g_lock);
}

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
        shim_message(s, fmi2Error, "fmi2Instantiate: the status shim cannot find its own file (dladdr failed)");
        goto out;
    }
    size_t len = strlen(info.dli_fname);
    if (len > 3 && strcmp(info.dli_fname + len - 3, ".so") == 0) len -= 3;
    path = (char*)malloc(len + sizeof SHIM_INNER_SUFFIX);
    if (!path) goto out;
    memcpy(path, info.dli_fname, len);
    memcpy(path + len, SHIM_INNER_SUFFIX, sizeof SHIM_INNER_SUFFIX);
    if (!prepare_python(s)) goto out;
    void* handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
        const char* why = dlerror();
        shim_message(s, fmi2Error, "fmi2Instantiate: the status shim cannot load %s: %s", path, why ? why : "?");
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

/* ---- the embedded interpreter at exit (who starts it, who finalizes it, and when) ----
 * pythonfmu 0.7 starts the interpreter in the first of its libraries instantiated in a process without Python:
 * a PyState held by that library's static std::shared_ptr owns it (its worker thread called Py_Initialize and
 * calls Py_Finalize when the PyState is destroyed). Every other pythonfmu library in the process finds Python
 * running and owns nothing. The owner's PyState is destroyed (1) by that library's exported
 * finalizePythonInterpreter(), (2) by the shared_ptr's static destructor, which runs among the exit handlers,
 * or (3) by its library destructor (onLibraryUnload), later, in _dl_fini; pythonfmu's libraries are never
 * really unloaded by dlclose (libstdc++ unique symbols pin them), so (2) is what happens in practice.
 * Two faults follow:
 *  - (2) runs among the exit handlers in the reverse order of registration, i.e. AFTER the C++ static
 *    destructors and exit handlers of every extension module imported later (SciPy, numba, OpenBLAS: they are
 *    loaded at the actuator's first fmi2Instantiate); Py_Finalize then frees objects whose memory those
 *    destructors already released and the host segfaults at exit (a C host: 8 of 10 runs with the actuator
 *    alone; 27 of 30 with a stock pythonfmu FMU instantiated first, which then owns the interpreter,
 *    gdb: unlink_chunk <- Py_FinalizeEx <- PyState::Worker of the other FMU, from __run_exit_handlers);
 *  - after (2), (3) assigns nullptr to the destroyed shared_ptr and releases its control block a second time
 *    (heap corruption: "corrupted double-linked list" in about 1 of 400 short fmpy runs).
 * The fix is to run (1) for every pythonfmu library in the process, the owner whichever FMU it belongs to,
 * before those destructors: from an exit handler registered at each fmi2Instantiate of this shim (after the
 * slave's imports; the last one registered runs first). (1) empties the shared_ptr, so the owner's worker
 * finalizes the interpreter there and then, on the thread that started it, and (2) and (3) find an empty
 * shared_ptr and do nothing. In a library that does not own the interpreter (a Python host such as fmpy: no
 * library owns it) (1) only drops a reference. The handler must run at exit, not when a host unloads the
 * actuator while another FMU still uses the interpreter, and atexit handlers of a shared library run when it
 * is unloaded: so the shim pins itself (RTLD_NODELETE) at the first fmi2Instantiate. The shim never finalizes
 * the interpreter itself and never before exit. */
#define SHIM_FINALIZE_SYMBOL "finalizePythonInterpreter"
#define SHIM_MAX_OBJECTS 1024

typedef struct { size_t n; char* names[SHIM_MAX_OBJECTS]; } ObjectList;

static int collect_object(struct dl_phdr_info* info, size_t size, void* data) {
    (void)size;
    ObjectList* list = (ObjectList*)data;
    if (info->dlpi_name && info->dlpi_name[0] && list->n < SHIM_MAX_OBJECTS) {
        char* copy = strdup(info->dlpi_name);
        if (copy) list->names[list->n++] = copy;
    }
    return 0;
}

/* call finalizePythonInterpreter of every loaded library that defines it (pythonfmu 0.7's binaries) */
static void finalize_pythonfmu_at_exit(void) {
    static ObjectList list;   /* static: no large stack frame at exit */
    list.n = 0;
    dl_iterate_phdr(collect_object, &list);   /* names only: no dlopen while the loader lock is held */
    for (size_t i = 0; i < list.n; ++i) {
        void* h = dlopen(list.names[i], RTLD_NOW | RTLD_NOLOAD);
        if (h) {
            void* f = dlsym(h, SHIM_FINALIZE_SYMBOL);
            Dl_info info;
            /* defined in this very object (dlsym on a handle also searches its dependencies) */
            if (f && dladdr(f, &info) && info.dli_fname && strcmp(info.dli_fname, list.names[i]) == 0) {
                void (*fin)(void);
                memcpy(&fin, &f, sizeof fin);   /* object -> function pointer (POSIX) */
                fin();
            }
            dlclose(h);
        }
        free(list.names[i]);
    }
    list.n = 0;
}

static void finalize_inner_python(void) {
    pthread_mutex_lock(&g_lock);
    void (*fin)(void) = g_finalize;
    pthread_mutex_unlock(&g_lock);
    if (fin) fin();
}

static void register_exit_finalization(void) {
    pthread_mutex_lock(&g_lock);
    if (g_handle && g_exit_registrations < 64) {
        if (g_exit_registrations == 0) {
            Dl_info info;
            if (dladdr((const void*)&g_lock, &info) && info.dli_fname)
                (void)dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);  /* pin this library */
        }
        if (atexit(finalize_pythonfmu_at_exit) == 0) ++g_exit_registrations;
    }
    pthread_mutex_unlock(&g_lock);
}

/* runs in _dl_fini (the shim is pinned), after the exit handlers: normally nothing is left to do */
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
    restore_python_env();
    register_exit_finalization();  /* after the slave's imports (also when they failed: Python may be running) */
    if (!s->inner) {
        shim_message(s, fmi2Error, "fmi2Instantiate: the Python slave could not be started (see the message "
                     "before). It needs Python 3.11 with numpy, scipy and numba; the interpreter came from %s. "
                     "Set %s to a JSON file describing such a Python (see README.md, \"Using the FMU in a system "
                     "simulator\"), or rebuild the FMU on this machine (`make fmu`)", g_python_source,
                     SHIM_PYTHON_ENV);
        return 0;
    }
    s->state = SHIM_OK;
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

/* ---- FMU state save/restore ----
 * pythonfmu 0.7 hands the slave's state object (a PyObject*) to the host as the fmi2FMUstate itself: a freed
 * or foreign pointer is dereferenced (a crash), fmi2SerializeFMUstate ignores the buffer size, a slave
 * exception is fmi2Fatal with a broken instance, and the serialized bytes carry nothing naming the model. So
 * the shim keeps its own FMU-state objects: fmi2GetFMUstate asks the slave for its state (bytes; see
 * _get_fmu_state in fmu_src/mpc_actuator.py) through the inner library and keeps a copy; fmi2SetFMUstate hands
 * such bytes back (_set_fmu_state validates them and reports a recoverable error). Only pointers this shim
 * returned and has not freed are accepted (a registry, searched by pointer value: a freed, foreign or NULL
 * pointer is fmi2Error, never dereferenced). Serialized form (little-endian):
 *   "MPCFMUST" | u32 format version (1) | u32 n + modelIdentifier | u32 n + GUID | u64 n + slave bytes |
 *   u64 FNV-1a hash of everything before it
 * fmi2DeSerializeFMUstate checks all of it (a state of another model, garbage, or truncated bytes: fmi2Error
 * with a message saying which). States are freed with their instance. */
#define SHIM_STATE_MAGIC "MPCFMUST"
#define SHIM_STATE_VERSION 1u

typedef struct ShimFMUState {
    struct ShimFMUState* next;
    const Shim* owner;
    size_t size;
    unsigned char* bytes;   /* the slave's state */
} ShimFMUState;

static ShimFMUState* g_states;   /* registry (g_lock) */
static char g_model_id[256];     /* this library's file name without .so (= modelIdentifier) */

static const char* model_identifier(void) {
    pthread_mutex_lock(&g_lock);
    if (!g_model_id[0]) {
        Dl_info info;
        const char* name = (dladdr((const void*)&g_lock, &info) && info.dli_fname) ? info.dli_fname : "?";
        const char* base = strrchr(name, '/');
        snprintf(g_model_id, sizeof g_model_id, "%s", base ? base + 1 : name);
        size_t n = strlen(g_model_id);
        if (n > 3 && strcmp(g_model_id + n - 3, ".so") == 0) g_model_id[n - 3] = '\0';
    }
    pthread_mutex_unlock(&g_lock);
    return g_model_id;
}

static ShimFMUState* find_state(fmi2FMUstate p) {   /* with g_lock held */
    for (ShimFMUState* st = g_states; st; st = st->next)
        if ((void*)st == p) return st;
    return NULL;
}

static int state_known(fmi2FMUstate p) {
    pthread_mutex_lock(&g_lock);
    int known = p && find_state(p) != NULL;
    pthread_mutex_unlock(&g_lock);
    return known;
}

static void unregister_state(ShimFMUState* st) {
    pthread_mutex_lock(&g_lock);
    for (ShimFMUState** pp = &g_states; *pp; pp = &(*pp)->next)
        if (*pp == st) { *pp = st->next; break; }
    pthread_mutex_unlock(&g_lock);
    free(st->bytes);
    free(st);
}

static void free_states_of(const Shim* s) {
    for (;;) {
        ShimFMUState* found = NULL;
        pthread_mutex_lock(&g_lock);
        for (ShimFMUState* st = g_states; st; st = st->next)
            if (st->owner == s) { found = st; break; }
        pthread_mutex_unlock(&g_lock);
        if (!found) return;
        unregister_state(found);
    }
}

static ShimFMUState* new_state(const Shim* s, const void* bytes, size_t size) {
    ShimFMUState* st = (ShimFMUState*)calloc(1, sizeof *st);
    unsigned char* copy = (unsigned char*)malloc(size ? size : 1);
    if (!st || !copy) { free(st); free(copy); return NULL; }
    if (size) memcpy(copy, bytes, size);
    st->owner = s;
    st->size = size;
    st->bytes = copy;
    pthread_mutex_lock(&g_lock);
    st->next = g_states;
    g_states = st;
    pthread_mutex_unlock(&g_lock);
    return st;
}

/* The state p when it is one of this instance's (made by its fmi2GetFMUstate or fmi2DeSerializeFMUstate), else
 * NULL; when p is a state of another instance of this FMU, that instance's name is copied into other (FMI 2.0
 * ties an FMU state to the instance it came from: it moves to another one only serialized). With g_lock held. */
static ShimFMUState* find_own_state(const Shim* s, fmi2FMUstate p, char* other, size_t n) {
    ShimFMUState* st = p ? find_state(p) : NULL;
    other[0] = '\0';
    if (st && st->owner != s) {
        snprintf(other, n, "%s", st->owner->instance_name ? st->owner->instance_name : "?");
        return NULL;
    }
    return st;
}

static void foreign_state_message(Shim* s, const char* call, const char* other) {
    shim_message(s, fmi2Error, "%s: the FMUstate belongs to the instance '%s', not to this one ('%s'): an FMU "
                 "state is only valid in the instance that made it (move it with fmi2SerializeFMUstate and "
                 "fmi2DeSerializeFMUstate)", call, other, s->instance_name ? s->instance_name : "?");
}

static const char* NOT_A_STATE = "is not an FMU state of this FMU: NULL, already freed (fmi2FreeFMUstate), freed "
                                 "with its instance, or from another FMU";

static fmi2Status shim_get_state(Shim* s, fmi2FMUstate* FMUstate) {
    if (!FMUstate) {
        shim_message(s, fmi2Error, "fmi2GetFMUstate: FMUstate is NULL");
        return fmi2Error;
    }
    if (*FMUstate) {
        char other[256];
        pthread_mutex_lock(&g_lock);
        int own = find_own_state(s, *FMUstate, other, sizeof other) != NULL;
        pthread_mutex_unlock(&g_lock);
        if (!own && other[0]) {
            foreign_state_message(s, "fmi2GetFMUstate", other);
            return fmi2Error;
        }
    }
    if (*FMUstate && !state_known(*FMUstate)) {
        shim_message(s, fmi2Error, "fmi2GetFMUstate: *FMUstate %s (pass a pointer to NULL for a new state)",
                     NOT_A_STATE);
        return fmi2Error;
    }
    fmi2Status st = shim_enter(s, "fmi2GetFMUstate");
    if (st != fmi2OK) return st;
    fmi2FMUstate py = NULL;
    size_t n = 0;
    if ((st = shim_leave(s, s->api->GetFMUstate(s->inner, &py))) != fmi2OK) {
        if (s->state == SHIM_OK && py) s->api->FreeFMUstate(s->inner, &py);
        return st;
    }
    s->error_logged = 0;
    st = shim_leave(s, s->api->SerializedFMUstateSize(s->inner, py, &n));
    char* buf = (st == fmi2OK) ? (char*)malloc(n ? n : 1) : NULL;
    if (st == fmi2OK && !buf) st = fmi2Error;
    if (st == fmi2OK) st = shim_leave(s, s->api->SerializeFMUstate(s->inner, py, buf, n));
    if (s->state == SHIM_OK) s->api->FreeFMUstate(s->inner, &py);
    if (st != fmi2OK) {
        free(buf);
        return st;
    }
    if (*FMUstate) {   /* overwrite the given state */
        pthread_mutex_lock(&g_lock);
        ShimFMUState* old = find_state(*FMUstate);
        if (old) {
            free(old->bytes);
            old->bytes = (unsigned char*)buf;
            old->size = n;
            buf = NULL;
        }
        pthread_mutex_unlock(&g_lock);
        free(buf);
        return old ? fmi2OK : fmi2Error;
    }
    ShimFMUState* created = new_state(s, buf, n);
    free(buf);
    if (!created) {
        shim_message(s, fmi2Error, "fmi2GetFMUstate: out of memory");
        return fmi2Error;
    }
    *FMUstate = created;
    return fmi2OK;
}

static fmi2Status shim_set_state(Shim* s, fmi2FMUstate FMUstate) {
    char other[256];
    pthread_mutex_lock(&g_lock);
    ShimFMUState* found = find_own_state(s, FMUstate, other, sizeof other);
    size_t n = found ? found->size : 0;
    char* copy = found ? (char*)malloc(n ? n : 1) : NULL;
    if (copy && n) memcpy(copy, found->bytes, n);
    pthread_mutex_unlock(&g_lock);
    if (!found && other[0]) {
        foreign_state_message(s, "fmi2SetFMUstate", other);
        return fmi2Error;
    }
    if (!found) {
        shim_message(s, fmi2Error, "fmi2SetFMUstate: the FMUstate %s", NOT_A_STATE);
        return fmi2Error;
    }
    if (!copy) return fmi2Error;
    fmi2Status st = shim_enter(s, "fmi2SetFMUstate");
    fmi2FMUstate py = NULL;
    if (st == fmi2OK) st = shim_leave(s, s->api->DeSerializeFMUstate(s->inner, copy, n, &py));
    free(copy);
    if (st != fmi2OK) return st;
    s->error_logged = 0;
    st = shim_leave(s, s->api->SetFMUstate(s->inner, py));
    if (s->state == SHIM_OK) s->api->FreeFMUstate(s->inner, &py);
    return st;
}

static fmi2Status shim_free_state(Shim* s, fmi2FMUstate* FMUstate) {
    if (!FMUstate || !*FMUstate) return fmi2OK;   /* FMI 2.0: a NULL state is ignored */
    char other[256];
    pthread_mutex_lock(&g_lock);
    ShimFMUState* found = find_own_state(s, *FMUstate, other, sizeof other);
    pthread_mutex_unlock(&g_lock);
    if (!found && other[0]) {
        foreign_state_message(s, "fmi2FreeFMUstate", other);
        return fmi2Error;
    }
    if (!found) {
        shim_message(s, fmi2Error, "fmi2FreeFMUstate: the FMUstate %s", NOT_A_STATE);
        return fmi2Error;
    }
    unregister_state(found);
    *FMUstate = NULL;
    return fmi2OK;
}

/* ---- serialized form ---- */
static uint64_t fnv1a(const unsigned char* p, size_t n) {
    uint64_t h = 1469598103934665603ull;
    for (size_t i = 0; i < n; ++i) { h ^= p[i]; h *= 1099511628211ull; }
    return h;
}

static void put_u32(unsigned char* p, uint32_t v) { for (int i = 0; i < 4; ++i) p[i] = (unsigned char)(v >> (8 * i)); }
static void put_u64(unsigned char* p, uint64_t v) { for (int i = 0; i < 8; ++i) p[i] = (unsigned char)(v >> (8 * i)); }
static uint32_t get_u32(const unsigned char* p) { uint32_t v = 0; for (int i = 3; i >= 0; --i) v = (v << 8) | p[i]; return v; }
static uint64_t get_u64(const unsigned char* p) { uint64_t v = 0; for (int i = 7; i >= 0; --i) v = (v << 8) | p[i]; return v; }

static size_t serialized_size(const Shim* s, size_t payload) {   /* model_identifier() called before */
    return 8 + 4 + 4 + strlen(g_model_id) + 4 + strlen(s->guid) + 8 + payload + 8;
}

static fmi2Status shim_serialized_size(Shim* s, fmi2FMUstate FMUstate, size_t* size) {
    (void)model_identifier();
    char other[256];
    pthread_mutex_lock(&g_lock);
    ShimFMUState* found = find_own_state(s, FMUstate, other, sizeof other);
    size_t n = found ? found->size : 0;
    pthread_mutex_unlock(&g_lock);
    if (!found && other[0]) {
        foreign_state_message(s, "fmi2SerializedFMUstateSize", other);
        return fmi2Error;
    }
    if (!found || !size) {
        shim_message(s, fmi2Error, "fmi2SerializedFMUstateSize: %s", size ? "the FMUstate is not an FMU state of "
                     "this FMU (NULL, freed, or from another FMU)" : "size is NULL");
        return fmi2Error;
    }
    *size = serialized_size(s, n);
    return fmi2OK;
}

static fmi2Status shim_serialize(Shim* s, fmi2FMUstate FMUstate, fmi2Byte out[], size_t size) {
    const char* id = model_identifier();   /* before g_lock: it takes the lock */
    char other[256];
    pthread_mutex_lock(&g_lock);
    ShimFMUState* found = find_own_state(s, FMUstate, other, sizeof other);
    size_t need = found ? serialized_size(s, found->size) : 0;
    fmi2Status st = fmi2OK;
    if (found && out && size == need) {
        unsigned char* p = (unsigned char*)out;
        memcpy(p, SHIM_STATE_MAGIC, 8); p += 8;
        put_u32(p, SHIM_STATE_VERSION); p += 4;
        put_u32(p, (uint32_t)strlen(id)); p += 4;
        memcpy(p, id, strlen(id)); p += strlen(id);
        put_u32(p, (uint32_t)strlen(s->guid)); p += 4;
        memcpy(p, s->guid, strlen(s->guid)); p += strlen(s->guid);
        put_u64(p, (uint64_t)found->size); p += 8;
        if (found->size) memcpy(p, found->bytes, found->size);
        p += found->size;
        put_u64(p, fnv1a((const unsigned char*)out, (size_t)(p - (unsigned char*)out)));
    } else {
        st = fmi2Error;
    }
    pthread_mutex_unlock(&g_lock);
    if (st != fmi2OK) {
        if (!found && other[0]) foreign_state_message(s, "fmi2SerializeFMUstate", other);
        else if (!found) shim_message(s, fmi2Error, "fmi2SerializeFMUstate: the FMUstate %s", NOT_A_STATE);
        else shim_message(s, fmi2Error, "fmi2SerializeFMUstate: size %zu, but the state needs %zu bytes "
                          "(fmi2SerializedFMUstateSize)%s", size, need, out ? "" : "; the buffer is NULL");
    }
    return st;
}

static fmi2Status shim_deserialize(Shim* s, const fmi2Byte in[], size_t size, fmi2FMUstate* FMUstate) {
    const unsigned char* p = (const unsigned char*)in;
    const char* id = model_identifier();
    const char* why = NULL;
    char detail[700] = "";
    if (!FMUstate) why = "FMUstate is NULL";
    else if (!in) why = "the byte array is NULL";
    else if (size < 8 + 4 + 4 || memcmp(p, SHIM_STATE_MAGIC, 8) != 0)
        why = "not a serialized FMU state of this FMU (no " SHIM_STATE_MAGIC " header)";
    else if (get_u32(p + 8) != SHIM_STATE_VERSION) {
        snprintf(detail, sizeof detail, "serialized with state format version %u; this FMU reads version %u",
                 get_u32(p + 8), SHIM_STATE_VERSION);
        why = detail;
    }
    size_t off = 12, n_id = 0, n_guid = 0, n_payload = 0;
    const unsigned char *sid = NULL, *sguid = NULL, *payload = NULL;
    if (!why) {
        n_id = get_u32(p + off); off += 4; sid = p + off;
        if (n_id > size - off || size - off - n_id < 4) why = "truncated (in the model identifier)";
        else { off += n_id; n_guid = get_u32(p + off); off += 4; sguid = p + off; }
        if (!why && (n_guid > size - off || size - off - n_guid < 8)) why = "truncated (in the GUID)";
        else if (!why) { off += n_guid; n_payload = (size_t)get_u64(p + off); off += 8; payload = p + off; }
        if (!why && (n_payload > size - off || size - off - n_payload != 8))
            why = "truncated or with trailing bytes (the length of the state does not match)";
        else if (!why && get_u64(p + off + n_payload) != fnv1a(p, off + n_payload)) why = "damaged (checksum)";
    }
    if (!why && (n_id != strlen(id) || memcmp(sid, id, n_id) != 0 || n_guid != strlen(s->guid) ||
                 memcmp(sguid, s->guid, n_guid) != 0)) {
        snprintf(detail, sizeof detail, "a state of model '%.*s' (GUID %.*s), not of this model '%s' (GUID %s)",
                 (int)(n_id < 200 ? n_id : 200), (const char*)sid, (int)(n_guid < 200 ? n_guid : 200),
                 (const char*)sguid, id, s->guid);
        why = detail;
    }
    if (why) {
        shim_message(s, fmi2Error, "fmi2DeSerializeFMUstate: %s", why);
        return fmi2Error;
    }
    ShimFMUState* created = new_state(s, payload, n_payload);
    if (!created) {
        shim_message(s, fmi2Error, "fmi2DeSerializeFMUstate: out of memory");
        return fmi2Error;
    }
    *FMUstate = created;
    return fmi2OK;
}

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
    free_states_of(s);
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

SHIM_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) {
    return c ? shim_get_state((Shim*)c, FMUstate) : fmi2Error;
}

SHIM_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    return c ? shim_set_state((Shim*)c, FMUstate) : fmi2Error;
}

SHIM_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* FMUstate) {
    return c ? shim_free_state((Shim*)c, FMUstate) : fmi2Error;
}

SHIM_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t* size) {
    return c ? shim_serialized_size((Shim*)c, FMUstate, size) : fmi2Error;
}

SHIM_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                             size_t size) {
    return c ? shim_serialize((Shim*)c, FMUstate, serializedState, size) : fmi2Error;
}

SHIM_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate* FMUstate) {
    return c ? shim_deserialize((Shim*)c, serializedState, size, FMUstate) : fmi2Error;
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
