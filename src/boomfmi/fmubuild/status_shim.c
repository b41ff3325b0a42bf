/*
 * status_shim.c: the entry library of every boomfmi FMU (binaries/linux64/<id>.so and,
 * where the build has mingw-w64, binaries/win64/<id>.dll).
 *
 * pythonfmu 0.7.0's binary runs the model in the host's Python: in a host that is not a
 * Python process it cannot even be loaded, and it turns every Python exception into
 * fmi2Fatal.  This shim sits in front of it (pythonfmu's own library is renamed
 * <id>_pythonfmu.so / <id>_pythonfmu.dll beside it) and forwards every FMI 2.0
 * co-simulation call, with these changes:
 *
 *  1. The Python runtime.  In a host without Python (a C or C++ tool) fmi2Instantiate
 *     first loads the Python the FMU was built with, as resources/boomfmi_runtime.txt
 *     records it (or $BOOMFMI_LIBPYTHON), globally, so that pythonfmu's library and
 *     numpy's extensions find its symbols; on Linux it also points the interpreter it
 *     starts at the build's home (PYTHONHOME, only for the build's own libpython and only
 *     if the environment does not set it, for the duration of that first
 *     fmi2Instantiate).  No site-packages of the build is used: the FMU's Python code
 *     checks its requirements (resources/boomfmi_requirements.txt) and a portable build
 *     carries its packages.  In a Python host (fmpy, libcosim's
 *     Python bindings) the interpreter is already running and nothing of this happens.
 *     When no runtime can be loaded, fmi2Instantiate logs what it looked for and why
 *     each candidate failed, at fmi2Error, and returns NULL.
 *  2. A host that goes on with an instance that fmi2Instantiate did not create (NULL)
 *     is stopped: the reason fmi2Instantiate failed goes to stderr and the process exits
 *     with status 1.  (The ecos command line does exactly that: its FMI layer wraps the
 *     NULL, ignores every status and shows FMU messages only at its debug level, so it
 *     would otherwise write zeros and exit 0.)  Hosts that check fmi2Instantiate's
 *     result never get here.
 *  3. A call's status is raised to the worst status the slave logged during that call:
 *     a Python slave reports a bad parameter by logging it with status fmi2Error, and
 *     the call then returns fmi2Error with that message.
 *  4. After pythonfmu reports fmi2Fatal (an unexpected Python exception) the instance
 *     is dead: later calls return fmi2Error without touching it, and
 *     fmi2FreeInstance does not hand pythonfmu an object it has already released.
 *     The failing call itself returns fmi2Error: other instances are unaffected.
 *  5. Messages reach the host's logger as "%s" arguments (pythonfmu passes them as the
 *     format string); warnings and errors always, the rest only with debug logging on;
 *     pythonfmu's fmi2Fatal as fmi2Error, the status the call returns.
 *  6. No fatal error inside an FMI call: in a host without Python the shim starts the
 *     interpreter itself (start_interpreter), after checking that PYTHONHOME, if set,
 *     holds the runtime's standard library; a start that fails is fmi2Error and NULL from
 *     fmi2Instantiate, naming the variable and what it found, never "Fatal Python error".
 *  7. A clean exit: pythonfmu's interpreter state is released before its static
 *     destructors run (release_inner_state; PythonFMU pull request 213's exit handler).
 *
 * Built by boomfmi.fmubuild with the FMI headers that fmpy ships: cc on Linux,
 * x86_64-w64-mingw32-gcc for Windows (the #ifdef _WIN32 parts).
 */
#ifdef _WIN32
#define WIN32_LEAN_AND_MEAN
#include <windows.h>
#include <psapi.h>
#else
#define _GNU_SOURCE
#include <dirent.h>
#include <dlfcn.h>
#include <sys/stat.h>
#endif
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"

#ifdef _WIN32
#define PLATFORM "win64"
#define INNER_SUFFIX "_pythonfmu.dll"
typedef HMODULE Library;
#else
#define PLATFORM "linux64"
#define INNER_SUFFIX "_pythonfmu.so"
typedef void *Library;
#endif

#define RECORD_NAME "boomfmi_runtime.txt"
#define LIBPYTHON_ENV "BOOMFMI_LIBPYTHON"
#define PATH_CHARS 4096
#define TEXT_CHARS 8192

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;    /* the host's callbacks */
    fmi2CallbackFunctions wrapped; /* what pythonfmu sees: our logger, this struct */
    fmi2Status worst;              /* worst status logged during the current call */
    int debug_logging;
    int dead;
    char *name;
    char *last_error;              /* the last error pythonfmu logged (kept while instantiating) */
} Shim;

#define FMI2_CS_FUNCTIONS(X)                                                         \
    X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetupExperiment)                    \
    X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate)    \
    X(fmi2Reset) X(fmi2CancelStep) X(fmi2GetReal) X(fmi2GetInteger)                 \
    X(fmi2GetBoolean) X(fmi2GetString) X(fmi2SetReal) X(fmi2SetInteger)              \
    X(fmi2SetBoolean) X(fmi2SetString) X(fmi2GetFMUstate) X(fmi2SetFMUstate)         \
    X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) X(fmi2SerializeFMUstate)       \
    X(fmi2DeSerializeFMUstate) X(fmi2GetDirectionalDerivative)                       \
    X(fmi2SetRealInputDerivatives) X(fmi2GetRealOutputDerivatives) X(fmi2DoStep)     \
    X(fmi2GetStatus) X(fmi2GetRealStatus) X(fmi2GetIntegerStatus)                    \
    X(fmi2GetBooleanStatus) X(fmi2GetStringStatus)

/* pythonfmu's functions, looked up when the first instance is made.  On Linux
 * pythonfmu's library is closed when the host closes this one (unload_inner), so that it
 * lives exactly as long as in a host that loaded it directly.  Left loaded past that,
 * its static destructors ran at process exit, after the interpreter they belong to: a
 * process that ran the FMUs in libcosim and then in fmpy aborted with a corrupted heap.
 * Closed any earlier (with the last instance), it finalised the interpreter under the
 * other FMUs of a non-Python host (ecos segfaulted at exit).  The Python runtime this
 * shim loads is never closed: an interpreter cannot be unloaded. */
static Library inner_lib = NULL;
static int live_instances = 0;
#ifndef _WIN32
/* pythonfmu's finalizePythonInterpreter (see release_inner_state). */
static void (*finalize_inner)(void) = NULL;
#endif
static struct {
#define DECLARE(fn) fn##TYPE *fn;
    FMI2_CS_FUNCTIONS(DECLARE)
#undef DECLARE
} inner;

#define INNER(fn) (inner.fn)

/* Why the last fmi2Instantiate of this FMU failed, for a host that goes on regardless. */
static char last_failure[TEXT_CHARS];

/* ------------------------------------------------------------------------------------
 * The platform: this library's own path, loading libraries, their errors.
 * ------------------------------------------------------------------------------------ */

static void append(char *buf, size_t size, const char *fmt, const char *a, const char *b) {
    size_t used = strlen(buf);
    if (used + 1 < size) snprintf(buf + used, size - used, fmt, a, b ? b : "");
}

#ifdef _WIN32
static int to_wide(const char *utf8, wchar_t *out, int chars) {
    return MultiByteToWideChar(CP_UTF8, 0, utf8, -1, out, chars) > 0;
}

static int to_utf8(const wchar_t *wide, char *out, int size) {
    return WideCharToMultiByte(CP_UTF8, 0, wide, -1, out, size, NULL, NULL) > 0;
}

static void last_error_text(char *out, size_t size) {
    DWORD code = GetLastError();
    char *msg = NULL;
    size_t n;
    FormatMessageA(FORMAT_MESSAGE_ALLOCATE_BUFFER | FORMAT_MESSAGE_FROM_SYSTEM | FORMAT_MESSAGE_IGNORE_INSERTS,
                   NULL, code, 0, (LPSTR)&msg, 0, NULL);
    snprintf(out, size, "error %lu: %s", (unsigned long)code, msg ? msg : "");
    if (msg) LocalFree(msg);
    n = strlen(out);
    while (n && (out[n - 1] == '\n' || out[n - 1] == '\r' || out[n - 1] == '.')) out[--n] = '\0';
}

static int own_path(char *out, size_t size) {
    HMODULE self = NULL;
    wchar_t wide[PATH_CHARS];
    if (!GetModuleHandleExW(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCWSTR)(void *)&own_path, &self))
        return 0;
    if (!GetModuleFileNameW(self, wide, PATH_CHARS)) return 0;
    return to_utf8(wide, out, (int)size);
}

/* Load a library; with a directory in its name, its own dependencies are looked for
 * beside it first (python3.dll and python3XY.dll, vcruntime next to them). */
static Library open_library(const char *path, int global, char *err, size_t err_size) {
    wchar_t wide[PATH_CHARS];
    Library lib;
    (void)global;
    if (!to_wide(path, wide, PATH_CHARS)) {
        snprintf(err, err_size, "not a valid path");
        return NULL;
    }
    lib = (strchr(path, '\\') || strchr(path, '/'))
              ? LoadLibraryExW(wide, NULL, LOAD_WITH_ALTERED_SEARCH_PATH)
              : LoadLibraryW(wide);
    if (!lib) last_error_text(err, err_size);
    return lib;
}

static void *library_symbol(Library lib, const char *name) {
    return (void *)GetProcAddress(lib, name);
}

static FILE *open_text(const char *path) {
    wchar_t wide[PATH_CHARS];
    return to_wide(path, wide, PATH_CHARS) ? _wfopen(wide, L"r") : NULL;
}

/* The module of this process that holds a Python runtime (Py_IsInitialized), or NULL. */
static HMODULE python_module(void) {
    HMODULE modules[1024];
    DWORD needed = 0, i, count;
    if (!EnumProcessModules(GetCurrentProcess(), modules, sizeof modules, &needed)) return NULL;
    count = needed / sizeof(HMODULE);
    if (count > 1024) count = 1024;
    for (i = 0; i < count; i++) {
        if (GetProcAddress(modules[i], "Py_IsInitialized")) return modules[i];
    }
    return NULL;
}

/* Py_IsInitialized of a Python already in this process, and the file that holds it. */
static void *python_in_process(char *where, size_t size) {
    HMODULE module = python_module();
    wchar_t wide[PATH_CHARS];
    if (!module) return NULL;
    where[0] = '\0';
    if (GetModuleFileNameW(module, wide, PATH_CHARS)) to_utf8(wide, where, (int)size);
    return (void *)GetProcAddress(module, "Py_IsInitialized");
}
#else
static int own_path(char *out, size_t size) {
    Dl_info info;
    if (!dladdr((void *)&own_path, &info) || !info.dli_fname) return 0;
    if (strlen(info.dli_fname) + 1 > size) return 0;
    strcpy(out, info.dli_fname);
    return 1;
}

static Library open_library(const char *path, int global, char *err, size_t err_size) {
    Library lib = dlopen(path, RTLD_NOW | (global ? RTLD_GLOBAL : RTLD_LOCAL));
    if (!lib) {
        const char *e = dlerror();
        snprintf(err, err_size, "%s", e ? e : "unknown dlopen error");
    }
    return lib;
}

static void *library_symbol(Library lib, const char *name) { return dlsym(lib, name); }

static FILE *open_text(const char *path) { return fopen(path, "r"); }

static void *python_in_process(char *where, size_t size) {
    Dl_info info;
    void *fn = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    where[0] = '\0';
    if (fn && dladdr(fn, &info) && info.dli_fname && strlen(info.dli_fname) < size)
        strcpy(where, info.dli_fname);
    return fn;
}

static int same_file(const char *a, const char *b) {
    struct stat sa, sb;
    return a[0] && b[0] && stat(a, &sa) == 0 && stat(b, &sb) == 0 && sa.st_dev == sb.st_dev &&
           sa.st_ino == sb.st_ino;
}
#endif

/* The directory of this library, with its separator: <fmu>/binaries/<platform>/ */
static size_t own_dir(char *out, size_t size) {
    char *slash;
    if (!own_path(out, size)) return 0;
    slash = strrchr(out, '/');
#ifdef _WIN32
    {
        char *back = strrchr(out, '\\');
        if (!slash || (back && back > slash)) slash = back;
    }
#endif
    if (!slash) return 0;
    slash[1] = '\0';
    return (size_t)(slash + 1 - out);
}

/* ------------------------------------------------------------------------------------
 * The Python runtime.
 * ------------------------------------------------------------------------------------ */

/* resources/boomfmi_runtime.txt: key=value lines that the build writes. */
static struct {
    int read;
    char file[PATH_CHARS];
    char problem[PATH_CHARS + 128]; /* why it could not be read, if it could not */
    char version[32];               /* 3.11 */
    char libpython[PATH_CHARS];     /* PLATFORM.libpython: the build's shared libpython */
    char soname[256];               /* PLATFORM.soname: its name, for the loader's own search */
    char home[PATH_CHARS];          /* PLATFORM.home: sys.base_prefix */
    char path[TEXT_CHARS];          /* PLATFORM.path: the site-packages that hold numpy */
} record;

static void read_record(void) {
    FILE *f;
    char line[TEXT_CHARS + 64];
    size_t dir_len;
    if (record.read) return;
    record.read = 1;
    dir_len = own_dir(record.file, sizeof record.file);
    if (!dir_len || dir_len + 32 > sizeof record.file) {
        snprintf(record.problem, sizeof record.problem, "cannot tell where this FMU was unpacked");
        return;
    }
    strcat(record.file, "../../resources/" RECORD_NAME);
    f = open_text(record.file);
    if (!f) {
        snprintf(record.problem, sizeof record.problem, "%s: %s", record.file, strerror(errno));
        return;
    }
    while (fgets(line, sizeof line, f)) {
        char *eq, *value;
        size_t n = strlen(line);
        while (n && (line[n - 1] == '\n' || line[n - 1] == '\r')) line[--n] = '\0';
        if (line[0] == '#' || !(eq = strchr(line, '='))) continue;
        *eq = '\0';
        value = eq + 1;
#define FIELD(key, dst)                                                   \
        if (strcmp(line, key) == 0) {                                     \
            snprintf(dst, sizeof dst, "%s", value);                       \
            continue;                                                     \
        }
        FIELD("version", record.version)
        FIELD(PLATFORM ".libpython", record.libpython)
        FIELD(PLATFORM ".soname", record.soname)
        FIELD(PLATFORM ".home", record.home)
        FIELD(PLATFORM ".path", record.path)
#undef FIELD
    }
    fclose(f);
}

#ifndef _WIN32
/* The environment variables set for the interpreter pythonfmu starts, undone after. */
static int set_home = 0, set_path = 0;

static void point_interpreter_at_build(const char *runtime) {
    if (!getenv("PYTHONHOME") && record.home[0] && same_file(runtime, record.libpython)) {
        setenv("PYTHONHOME", record.home, 1);
        set_home = 1;
    }
    if (!getenv("PYTHONPATH") && record.path[0]) {
        setenv("PYTHONPATH", record.path, 1);
        set_path = 1;
    }
}

static void restore_environment(void) {
    if (set_home) unsetenv("PYTHONHOME");
    if (set_path) unsetenv("PYTHONPATH");
    set_home = set_path = 0;
}
#else
static void restore_environment(void) {}
#endif

typedef int PyIsInitializedFn(void);

/* Starting the interpreter.  In a host without Python the shim starts it itself, before
 * pythonfmu's library is loaded, with Py_InitializeFromConfig (Python 3.8 on), which
 * returns a failure as a PyStatus where Py_Initialize (what pythonfmu calls) ends the
 * process with "Fatal Python error".  pythonfmu then finds it running and never starts
 * or finalises one of its own (its PyState keeps no interpreter), so that the
 * interpreter's life no longer hangs on pythonfmu's static objects (see
 * release_inner_state).  The config is Py_Initialize's own (_PyConfig_InitCompatConfig)
 * where the runtime exports it, else the "Python" config; either reads PYTHONHOME and
 * PYTHONPATH from the environment.  The interpreter is never finalised. */
typedef struct {            /* PyStatus, the same layout from Python 3.8 on */
    int type;               /* 0 ok, 1 error, 2 exit */
    const char *func;
    const char *err_msg;
    int exitcode;
} PyStatusABI;
typedef void PyConfigInitFn(void *config);
typedef PyStatusABI PyInitializeFromConfigFn(const void *config);
typedef void PyConfigClearFn(void *config);
typedef void *PyEvalSaveThreadFn(void);
typedef const char *PyGetVersionFn(void);

/* Why the interpreter could not start: it cannot be started twice in one process. */
static char start_failure[TEXT_CHARS];

#ifdef _WIN32
static void *runtime_symbol(const char *name) {
    HMODULE module = python_module();
    return module ? (void *)GetProcAddress(module, name) : NULL;
}
#define SEP "\\"
#define STDLIB_DIR "Lib%.0s"      /* the version is not part of it on Windows */
#else
static void *runtime_symbol(const char *name) { return dlsym(RTLD_DEFAULT, name); }
#define SEP "/"
#define STDLIB_DIR "lib" SEP "python%s"
#endif

/* PYTHONHOME, when set, must hold the standard library of the runtime's version: else
 * the interpreter cannot import encodings and (through Py_Initialize) ends the process. */
static int check_home(const char *runtime, const char *version, char *why, size_t why_size) {
    const char *home = getenv("PYTHONHOME");
    char prefix[PATH_CHARS], stdlib[PATH_CHARS + 64], encodings[PATH_CHARS + 96], found[TEXT_CHARS] = "";
    FILE *f;
    size_t n;
    if (!home || !home[0]) return 1;
    n = strcspn(home, ":");         /* prefix[:exec_prefix] */
#ifdef _WIN32
    n = strlen(home);
#endif
    snprintf(prefix, sizeof prefix, "%.*s", (int)n, home);
    snprintf(stdlib, sizeof stdlib, "%s" SEP STDLIB_DIR, prefix, version);
    snprintf(encodings, sizeof encodings, "%s" SEP "encodings" SEP "__init__.py", stdlib);
    f = open_text(encodings);
    if (f) {
        fclose(f);
        return 1;
    }
    snprintf(found, sizeof found, "%s: %s", encodings, strerror(errno));
#ifndef _WIN32
    {
        char lib[PATH_CHARS + 8];
        DIR *d;
        struct dirent *e;
        int any = 0;
        snprintf(lib, sizeof lib, "%s/lib", prefix);
        d = opendir(lib);
        if (!d) {
            append(found, sizeof found, "; %s: %s", lib, strerror(errno));
        } else {
            while ((e = readdir(d)) != NULL) {
                if (strncmp(e->d_name, "python", 6) != 0) continue;
                append(found, sizeof found, any ? ", %s%s" : "; it holds the standard library of another Python: %s%s",
                       e->d_name, NULL);
                any = 1;
            }
            closedir(d);
            if (!any) append(found, sizeof found, "; %s holds no python3.X folder%s", lib, NULL);
        }
    }
#endif
    snprintf(why, why_size,
             "PYTHONHOME=%s does not hold the standard library of Python %s, the runtime this FMU "
             "loaded (%s): %s. The interpreter cannot start with it; unset PYTHONHOME, or set it to "
             "that Python's prefix (the folder that holds " STDLIB_DIR ").",
             home, version, runtime, found, version);
    return 0;
}

static int start_interpreter(const char *runtime, char *why, size_t why_size) {
    static double config[1024];     /* a PyConfig: 424 bytes in Python 3.11, room for later ones */
    PyConfigInitFn *config_init = (PyConfigInitFn *)runtime_symbol("_PyConfig_InitCompatConfig");
    PyInitializeFromConfigFn *init = (PyInitializeFromConfigFn *)runtime_symbol("Py_InitializeFromConfig");
    PyConfigClearFn *clear = (PyConfigClearFn *)runtime_symbol("PyConfig_Clear");
    PyEvalSaveThreadFn *save = (PyEvalSaveThreadFn *)runtime_symbol("PyEval_SaveThread");
    PyGetVersionFn *get_version = (PyGetVersionFn *)runtime_symbol("Py_GetVersion");
    PyStatusABI status;
    char version[32] = "";
    const char *v, *home, *path;
    if (start_failure[0]) {
        snprintf(why, why_size, "%s", start_failure);
        return 0;
    }
    if (!config_init) config_init = (PyConfigInitFn *)runtime_symbol("PyConfig_InitPythonConfig");
    if (!config_init || !init || !clear || !save || !get_version) {
        snprintf(why, why_size, "the Python runtime %s has no Py_InitializeFromConfig: it is older than "
                 "Python 3.8; this FMU needs Python %s", runtime, record.version[0] ? record.version : "3");
        return 0;
    }
    v = get_version();              /* "3.11.2 (main, ...)": safe before the start */
    {
        const char *dot = strchr(v, '.');
        size_t n = dot ? strspn(dot + 1, "0123456789") + (size_t)(dot + 1 - v) : strcspn(v, " ");
        if (n >= sizeof version) n = sizeof version - 1;
        memcpy(version, v, n);
        version[n] = '\0';
    }
    if (record.version[0] && strcmp(version, record.version) != 0) {
        snprintf(why, why_size, "the Python runtime %s is Python %s; this FMU needs Python %s "
                 "(set " LIBPYTHON_ENV " to a Python %s runtime's shared library)",
                 runtime, version, record.version, record.version);
        return 0;
    }
    if (!check_home(runtime, version, why, why_size)) return 0;
    memset(config, 0, sizeof config);
    config_init(config);
    status = init(config);
    clear(config);
    if (status.type != 0) {
        home = getenv("PYTHONHOME");
        path = getenv("PYTHONPATH");
        snprintf(start_failure, sizeof start_failure,
                 "the Python runtime %s could not start: %s%s%s (exit code %d) "
                 "(PYTHONHOME=%s, PYTHONPATH=%s); no FMU can run Python in this process now",
                 runtime, status.func ? status.func : "", status.func ? ": " : "",
                 status.err_msg ? status.err_msg : "no message", status.type == 2 ? status.exitcode : 1,
                 home ? home : "(not set)", path ? path : "(not set)");
        snprintf(why, why_size, "%s", start_failure);
        return 0;
    }
    save();                         /* release the GIL: pythonfmu takes it per call */
    return 1;
}

/* Try one candidate for the runtime; note the failure in `tried`. */
static Library try_runtime(const char *candidate, char *tried, size_t tried_size) {
    char err[1024];
    Library lib;
    if (!candidate[0]) return NULL;
    lib = open_library(candidate, 1, err, sizeof err);
    if (!lib) append(tried, tried_size, "\n  %s: %s", candidate, err);
    return lib;
}

#ifdef _WIN32
/* The install folder that the Python installer records (PEP 514), as <dir>\python3XY.dll */
static int registered_python(const char *version, const char *dll, char *out, size_t size) {
    static const HKEY roots[] = {HKEY_CURRENT_USER, HKEY_LOCAL_MACHINE};
    wchar_t key[128] = L"Software\\Python\\PythonCore\\", wide_version[32], dir[PATH_CHARS];
    char dir8[PATH_CHARS];
    int i;
    if (!to_wide(version, wide_version, 32)) return 0;
    wcscat(key, wide_version);
    wcscat(key, L"\\InstallPath");
    for (i = 0; i < 2; i++) {
        DWORD bytes = sizeof dir;
        if (RegGetValueW(roots[i], key, NULL, RRF_RT_REG_SZ, NULL, dir, &bytes) == ERROR_SUCCESS &&
            to_utf8(dir, dir8, sizeof dir8)) {
            size_t n = strlen(dir8);
            snprintf(out, size, "%s%s%s", dir8, (n && dir8[n - 1] == '\\') ? "" : "\\", dll);
            return 1;
        }
    }
    return 0;
}

/* pythonfmu's DLL imports python3.dll (the stable ABI), which forwards to python3XY.dll:
 * load the one beside the runtime, so that the loader finds it by name.  (pythonfmu's DLL
 * is loaded with LOAD_WITH_ALTERED_SEARCH_PATH, which searches its own folder and the
 * system's, not the host executable's: even in python.exe python3.dll must be loaded.) */
static void load_stable_abi_beside(const char *runtime) {
    char path[PATH_CHARS], err[512];
    char *slash;
    snprintf(path, sizeof path, "%s", runtime);
    slash = strrchr(path, '\\');
    if (!slash) slash = strrchr(path, '/');
    if (!slash || (size_t)(slash - path) + 16 > sizeof path) return;
    strcpy(slash + 1, "python3.dll");
    open_library(path, 1, err, sizeof err);
}
#endif

/* Make sure a Python runtime is in the process before pythonfmu's library is loaded.
 * Returns 1 when there is one (and prepares the interpreter pythonfmu starts), else 0
 * with the reason in `why`.  `runtime` gets the file that holds it. */
static int ensure_python(char *why, size_t why_size, char *runtime, size_t runtime_size) {
    PyIsInitializedFn *initialized = (PyIsInitializedFn *)python_in_process(runtime, runtime_size);
    const char *override;
    char tried[TEXT_CHARS] = "";
    Library lib = NULL;
    if (initialized && initialized()) {             /* a Python host: change nothing */
#ifdef _WIN32
        load_stable_abi_beside(runtime);    /* python.exe's folder is not searched for it */
#endif
        return 1;
    }
    read_record();
    if (!initialized) {
        override = getenv(LIBPYTHON_ENV);
        if (override && override[0]) {
            lib = try_runtime(override, tried, sizeof tried);
            if (!lib) {
                snprintf(why, why_size,
                         "cannot load the Python runtime that " LIBPYTHON_ENV " names:%s", tried);
                return 0;
            }
        } else {
#ifdef _WIN32
            char dll[64] = "", registered[PATH_CHARS] = "";
            if (record.version[0]) {
                const char *dot = strchr(record.version, '.');
                if (dot) snprintf(dll, sizeof dll, "python%.*s%s.dll", (int)(dot - record.version),
                                  record.version, dot + 1);
            }
            lib = try_runtime(record.libpython, tried, sizeof tried);
            if (!lib && dll[0] && registered_python(record.version, dll, registered, sizeof registered))
                lib = try_runtime(registered, tried, sizeof tried);
            if (!lib && dll[0]) lib = try_runtime(dll, tried, sizeof tried);
#else
            lib = try_runtime(record.libpython, tried, sizeof tried);
            if (!lib) lib = try_runtime(record.soname, tried, sizeof tried);
#endif
            if (!lib) {
                snprintf(why, why_size,
                         "cannot load the Python runtime this FMU needs (Python %s with numpy; "
                         "the FMU runs its model in Python). Tried:%s%s%s%s\n"
                         "Install that Python, set " LIBPYTHON_ENV " to the path of its shared "
                         "library (libpython3.X.so / python3X.dll), or run the FMU in a Python "
                         "process (fmpy).",
                         record.version[0] ? record.version : "3",
                         tried[0] ? tried : " nothing",
                         record.problem[0] ? "\n  (the build's record of its runtime could not be read: " : "",
                         record.problem[0] ? record.problem : "", record.problem[0] ? ")" : "");
                return 0;
            }
        }
        initialized = (PyIsInitializedFn *)library_symbol(lib, "Py_IsInitialized");
        if (!initialized) {
            snprintf(why, why_size, "the library loaded as the Python runtime has no Py_IsInitialized:%s",
                     tried[0] ? tried : "");
            return 0;
        }
#ifdef _WIN32
        {
            wchar_t wide[PATH_CHARS];
            runtime[0] = '\0';
            if (GetModuleFileNameW(lib, wide, PATH_CHARS)) to_utf8(wide, runtime, (int)runtime_size);
        }
#else
        python_in_process(runtime, runtime_size);   /* the file the loader actually took */
#endif
    }
#ifdef _WIN32
    load_stable_abi_beside(runtime);
#else
    point_interpreter_at_build(runtime);
#endif
    return start_interpreter(runtime, why, why_size);
}

/* ------------------------------------------------------------------------------------
 * pythonfmu's library.
 * ------------------------------------------------------------------------------------ */

#ifndef _WIN32
/* pythonfmu 0.7.0 keeps its interpreter state in a static std::shared_ptr (pyState, made
 * in pythonfmu::createInstance) and resets it in a library destructor
 * (finalizePythonInterpreter), the change of PythonFMU pull request 213 ("Fix the crash
 * that occurs on the second attempt to instantiate the FMU").  Its library cannot be
 * unloaded (dlclose leaves it mapped), so both run at process exit, in the wrong order:
 * the shared_ptr's static destructor (an exit handler) frees the PyState first, then the
 * library destructor assigns to the destroyed shared_ptr and frees the block again:
 * "free(): corrupted unsorted chunks", exit status 134, in a plain C host that had
 * returned 0 from main (valgrind: an invalid read in finalizePythonInterpreter of a
 * block an exit handler freed).  The shim calls finalizePythonInterpreter itself
 * before either: from an exit handler registered after pythonfmu's library was loaded
 * (so it runs before that library's static destructors), and when the host unloads
 * this library.  Calling it is harmless at any time: the interpreter is the shim's or
 * the host's (start_interpreter), so the PyState it releases holds none. */
static void release_inner_state(void) {
    if (finalize_inner) finalize_inner();
}
#endif

static int load_inner(char *why, size_t why_size) {
    char path[PATH_CHARS], err[1024];
    size_t dir_len;
    const char *base, *dot;
    size_t base_len;
    if (inner_lib) return 1;
    memset(&inner, 0, sizeof inner);
    dir_len = own_dir(path, sizeof path);
    if (!dir_len || !own_path(err, sizeof err)) {
        snprintf(why, why_size, "cannot tell where this FMU's binary is");
        return 0;
    }
    /* <dir>/<id>.so -> <dir>/<id>_pythonfmu.so */
    base = err + dir_len;
    dot = strrchr(base, '.');
    base_len = dot ? (size_t)(dot - base) : strlen(base);
    if (dir_len + base_len + strlen(INNER_SUFFIX) + 1 > sizeof path) {
        snprintf(why, why_size, "the FMU's path is too long");
        return 0;
    }
    memcpy(path + dir_len, base, base_len);
    strcpy(path + dir_len + base_len, INNER_SUFFIX);
    inner_lib = open_library(path, 0, err, sizeof err);
    if (!inner_lib) {
        snprintf(why, why_size, "cannot load the FMU's pythonfmu library %s: %s", path, err);
#ifdef _WIN32
        {
            wchar_t wide[PATH_CHARS];
            if (to_wide(path, wide, PATH_CHARS) && GetFileAttributesW(wide) != INVALID_FILE_ATTRIBUTES)
                append(why, why_size, "%s%s",
                       " (the file is there: a library it needs is missing, python3.dll beside the "
                       "Python runtime or the Microsoft Visual C++ runtime, msvcp140.dll)", NULL);
        }
#endif
        return 0;
    }
#define LOOKUP(fn) inner.fn = (fn##TYPE *)library_symbol(inner_lib, #fn);
    FMI2_CS_FUNCTIONS(LOOKUP)
#undef LOOKUP
#ifndef _WIN32
    finalize_inner = (void (*)(void))library_symbol(inner_lib, "finalizePythonInterpreter");
    if (finalize_inner) atexit(release_inner_state);
#endif
    if (inner.fmi2Instantiate == NULL || inner.fmi2DoStep == NULL) {
        snprintf(why, why_size, "%s is not an FMI 2.0 co-simulation library", path);
        return 0;
    }
    return 1;
}

static void shim_logger(fmi2ComponentEnvironment env, fmi2String instanceName,
                        fmi2Status status, fmi2String category, fmi2String message, ...) {
    Shim *s = (Shim *)env;
    if (!s) return;
    if (status > s->worst) s->worst = status;
    if (status >= fmi2Error && message && !s->inner) {     /* while instantiating */
        free(s->last_error);
        s->last_error = strdup(message);
    }
    /* pythonfmu logs an exception with fmi2Fatal; the call returns fmi2Error (finish) */
    if (s->host.logger && (status >= fmi2Warning || s->debug_logging))
        s->host.logger(s->host.componentEnvironment, instanceName, status == fmi2Fatal ? fmi2Error : status,
                       category ? category : "logAll", "%s", message ? message : "");
}

static void host_log(Shim *s, fmi2Status status, const char *message) {
    if (s->host.logger && (status >= fmi2Warning || s->debug_logging))
        s->host.logger(s->host.componentEnvironment, s->name, status,
                       status >= fmi2Warning ? "logStatusError" : "logAll", "%s", message);
}

/* A host called fmiXxx on an instance fmi2Instantiate did not create: say why it was
 * not created, on stderr (the host may show FMU messages only at a debug level), and
 * stop, rather than let it simulate without the model. */
__attribute__((noreturn)) static void stop_the_host(const char *function) {
    char fmu[PATH_CHARS] = "";
    char *name = fmu;
    if (own_path(fmu, sizeof fmu)) {
        char *slash = strrchr(fmu, '/');
#ifdef _WIN32
        char *back = strrchr(fmu, '\\');
        if (!slash || (back && back > slash)) slash = back;
#endif
        if (slash) name = slash + 1;
        if (strrchr(name, '.')) *strrchr(name, '.') = '\0';   /* the model identifier */
    }
    fprintf(stderr,
            "boomfmi FMU %s: the host called %s on an instance that fmi2Instantiate did not create.\n"
            "%s"
            "boomfmi FMU %s: stopping the process (exit status 1) rather than simulating without the model.\n",
            name, function, last_failure, name);
    fflush(stderr);
    _exit(1);
}

#define GUARD(c)                                                                    \
    Shim *s = (Shim *)(c);                                                          \
    if (!s) stop_the_host(__func__);                                                \
    if (s->dead) {                                                                  \
        host_log(s, fmi2Error, "this instance failed earlier and cannot be used");   \
        return fmi2Error;                                                           \
    }                                                                               \
    s->worst = fmi2OK;

/* Forward one call and fold the logged status into its return value. */
static fmi2Status finish(Shim *s, fmi2Status st) {
    if (st == fmi2Fatal) {
        s->dead = 1;
        host_log(s, fmi2Error, "the FMU's Python code raised an exception (see the message above); "
                               "this instance cannot continue");
        return fmi2Error;
    }
    if (s->worst > st && s->worst <= fmi2Error) st = s->worst;
    return st;
}

#ifndef _WIN32
/* When the host unloads this library, unload pythonfmu's with it: pythonfmu's own
 * library then lives exactly as long as it would in a host that loaded it directly.
 * (On Windows it stays: FreeLibrary must not be called while the loader unloads us.) */
__attribute__((destructor)) static void unload_inner(void) {
    if (inner_lib && live_instances == 0) {
        release_inner_state();
        finalize_inner = NULL;
        dlclose(inner_lib);
        inner_lib = NULL;
    }
}
#endif

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

static fmi2Component fail_instantiate(Shim *s, const char *why) {
    snprintf(last_failure, sizeof last_failure, "fmi2Instantiate of instance '%s' failed: %s\n", s->name, why);
    host_log(s, fmi2Error, why);
    free(s->last_error);
    free(s->name);
    free(s);
    return NULL;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Shim *s;
    char why[TEXT_CHARS], runtime[PATH_CHARS] = "";
    if (!functions) return NULL;
    s = (Shim *)calloc(1, sizeof(Shim));
    if (!s) return NULL;
    s->host = *functions;
    s->wrapped = *functions;
    s->wrapped.logger = shim_logger;
    s->wrapped.componentEnvironment = s;
    s->debug_logging = loggingOn ? 1 : 0;
    s->name = strdup(instanceName ? instanceName : "");
    why[0] = '\0';
    if (!ensure_python(why, sizeof why, runtime, sizeof runtime)) return fail_instantiate(s, why);
    if (!load_inner(why, sizeof why)) {
        restore_environment();
        return fail_instantiate(s, why);
    }
    if (runtime[0]) {
        snprintf(why, sizeof why, "Python runtime: %s", runtime);
        host_log(s, fmi2OK, why);
    }
    s->inner = INNER(fmi2Instantiate)(instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                      &s->wrapped, visible, fmi2True);
    if (!s->inner) {
        const char *python_path = getenv("PYTHONPATH");
        snprintf(why, sizeof why,
                 "pythonfmu could not instantiate the model: %s\n(Python runtime %s; PYTHONPATH=%s)",
                 s->last_error ? s->last_error : "see the message above",
                 runtime[0] ? runtime : "of the host process", python_path ? python_path : "");
        restore_environment();
        return fail_instantiate(s, why);
    }
    restore_environment();
    free(s->last_error);
    s->last_error = NULL;
    live_instances++;
    return (fmi2Component)s;
}

void fmi2FreeInstance(fmi2Component c) {
    Shim *s = (Shim *)c;
    if (!s) return;       /* FMI 2.0: a NULL instance is ignored */
    if (!s->dead) {
        /* a dead instance is left to leak: pythonfmu has already released its object */
        INNER(fmi2FreeInstance)(s->inner);
        --live_instances;
    }
    free(s->name);
    free(s);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    GUARD(c);
    (void)nCategories;
    (void)categories;
    s->debug_logging = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    GUARD(c);
    return finish(s, INNER(fmi2SetupExperiment)(s->inner, toleranceDefined, tolerance, startTime,
                                                stopTimeDefined, stopTime));
}

#define FORWARD0(fn)                                          \
    fmi2Status fn(fmi2Component c) {                          \
        GUARD(c);                                             \
        return finish(s, INNER(fn)(s->inner));                \
    }

FORWARD0(fmi2EnterInitializationMode)
FORWARD0(fmi2ExitInitializationMode)
FORWARD0(fmi2Terminate)
FORWARD0(fmi2Reset)
FORWARD0(fmi2CancelStep)

#define FORWARD_VALUES(fn, T)                                                         \
    fmi2Status fn(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, T value[]) { \
        GUARD(c);                                                                     \
        return finish(s, INNER(fn)(s->inner, vr, nvr, value));                        \
    }

FORWARD_VALUES(fmi2GetReal, fmi2Real)
FORWARD_VALUES(fmi2GetInteger, fmi2Integer)
FORWARD_VALUES(fmi2GetBoolean, fmi2Boolean)
FORWARD_VALUES(fmi2GetString, fmi2String)
FORWARD_VALUES(fmi2SetReal, const fmi2Real)
FORWARD_VALUES(fmi2SetInteger, const fmi2Integer)
FORWARD_VALUES(fmi2SetBoolean, const fmi2Boolean)
FORWARD_VALUES(fmi2SetString, const fmi2String)

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    GUARD(c);
    return finish(s, INNER(fmi2GetFMUstate)(s->inner, state));
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    GUARD(c);
    return finish(s, INNER(fmi2SetFMUstate)(s->inner, state));
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    GUARD(c);
    return finish(s, INNER(fmi2FreeFMUstate)(s->inner, state));
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    GUARD(c);
    return finish(s, INNER(fmi2SerializedFMUstateSize)(s->inner, state, size));
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    GUARD(c);
    return finish(s, INNER(fmi2SerializeFMUstate)(s->inner, state, bytes, size));
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state) {
    GUARD(c);
    return finish(s, INNER(fmi2DeSerializeFMUstate)(s->inner, bytes, size, state));
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    GUARD(c);
    return finish(s, INNER(fmi2GetDirectionalDerivative)(s->inner, vUnknown, nUnknown, vKnown,
                                                         nKnown, dvKnown, dvUnknown));
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    GUARD(c);
    return finish(s, INNER(fmi2SetRealInputDerivatives)(s->inner, vr, nvr, order, value));
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    GUARD(c);
    return finish(s, INNER(fmi2GetRealOutputDerivatives)(s->inner, vr, nvr, order, value));
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    GUARD(c);
    return finish(s, INNER(fmi2DoStep)(s->inner, currentCommunicationPoint, communicationStepSize,
                                       noSetFMUStatePriorToCurrentPoint));
}
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Status *value) {
    GUARD(c);
    return finish(s, INNER(fmi2GetStatus)(s->inner, kind, value));
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *value) {
    GUARD(c);
    return finish(s, INNER(fmi2GetRealStatus)(s->inner, kind, value));
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Integer *value) {
    GUARD(c);
    return finish(s, INNER(fmi2GetIntegerStatus)(s->inner, kind, value));
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Boolean *value) {
    GUARD(c);
    return finish(s, INNER(fmi2GetBooleanStatus)(s->inner, kind, value));
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind kind, fmi2String *value) {
    GUARD(c);
    return finish(s, INNER(fmi2GetStringStatus)(s->inner, kind, value));
}
