/*
 * status_shim.c: the entry library of every boomfmi FMU on Linux.
 *
 * pythonfmu 0.7.0's binary turns every Python exception into fmi2Fatal and frees the
 * instance's Python object, and it offers a Python slave no way to return fmi2Error
 * or fmi2Warning.  This shim sits in front of it (binaries/linux64/<id>.so; pythonfmu's
 * own library is renamed <id>_pythonfmu.so beside it) and forwards every FMI 2.0
 * co-simulation call, with three changes:
 *
 *  1. A call's status is raised to the worst status the slave logged during that call:
 *     a Python slave reports a bad parameter by logging it with status fmi2Error, and
 *     the call then returns fmi2Error with that message.
 *  2. After pythonfmu reports fmi2Fatal (an unexpected Python exception) the instance
 *     is dead: later calls return fmi2Error without touching it, and
 *     fmi2FreeInstance does not hand pythonfmu an object it has already released.
 *     The failing call itself returns fmi2Error: other instances are unaffected.
 *  3. Messages reach the host's logger as "%s" arguments (pythonfmu passes them as the
 *     format string); warnings and errors always, the rest only with debug logging on.
 *
 * Built by boomfmi.fmubuild with the FMI headers that fmpy ships.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifndef INNER_SUFFIX
#define INNER_SUFFIX "_pythonfmu.so"
#endif

typedef struct {
    fmi2Component inner;
    fmi2CallbackFunctions host;    /* the host's callbacks */
    fmi2CallbackFunctions wrapped; /* what pythonfmu sees: our logger, this struct */
    fmi2Status worst;              /* worst status logged during the current call */
    int debug_logging;
    int dead;
    char *name;
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

/* pythonfmu's functions, looked up when the first instance is made.  pythonfmu's
 * library is closed when the host closes this one (unload_inner), so that it lives
 * exactly as long as in a host that loaded it directly.  Left loaded past that, its
 * static destructors ran at process exit, after the interpreter they belong to: a
 * process that ran the FMUs in libcosim and then in fmpy aborted with a corrupted
 * heap.  Closed any earlier (with the last instance), it finalised the interpreter
 * under the other FMUs of a non-Python host (ecos segfaulted at exit). */
static void *inner_lib = NULL;
static int live_instances = 0;
static struct {
#define DECLARE(fn) fn##TYPE *fn;
    FMI2_CS_FUNCTIONS(DECLARE)
#undef DECLARE
} inner;

#define INNER(fn) (inner.fn)

static int load_inner(void) {
    Dl_info info;
    char path[4096];
    const char *slash;
    size_t dir_len;
    if (inner_lib) return 1;
    memset(&inner, 0, sizeof inner);
    if (!dladdr((void *)&load_inner, &info) || !info.dli_fname) return 0;
    slash = strrchr(info.dli_fname, '/');
    dir_len = slash ? (size_t)(slash - info.dli_fname) + 1 : 0;
    /* <dir>/<id>.so -> <dir>/<id>_pythonfmu.so */
    {
        const char *base = slash ? slash + 1 : info.dli_fname;
        const char *dot = strrchr(base, '.');
        size_t base_len = dot ? (size_t)(dot - base) : strlen(base);
        if (dir_len + base_len + strlen(INNER_SUFFIX) + 1 > sizeof path) return 0;
        memcpy(path, info.dli_fname, dir_len);
        memcpy(path + dir_len, base, base_len);
        strcpy(path + dir_len + base_len, INNER_SUFFIX);
    }
    inner_lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!inner_lib) return 0;
#define LOOKUP(fn) inner.fn = (fn##TYPE *)dlsym(inner_lib, #fn);
    FMI2_CS_FUNCTIONS(LOOKUP)
#undef LOOKUP
    return inner.fmi2Instantiate != NULL && inner.fmi2DoStep != NULL;
}

static void shim_logger(fmi2ComponentEnvironment env, fmi2String instanceName,
                        fmi2Status status, fmi2String category, fmi2String message, ...) {
    Shim *s = (Shim *)env;
    if (!s) return;
    if (status > s->worst) s->worst = status;
    if (s->host.logger && (status >= fmi2Warning || s->debug_logging))
        s->host.logger(s->host.componentEnvironment, instanceName, status,
                       category ? category : "logAll", "%s", message ? message : "");
}

static void host_log(Shim *s, fmi2Status status, const char *message) {
    if (s->host.logger)
        s->host.logger(s->host.componentEnvironment, s->name, status, "logStatusError", "%s", message);
}

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

#define GUARD(c)                                                                    \
    Shim *s = (Shim *)(c);                                                          \
    if (!s) return fmi2Error;                                                       \
    if (s->dead) {                                                                  \
        host_log(s, fmi2Error, "this instance failed earlier and cannot be used");   \
        return fmi2Error;                                                           \
    }                                                                               \
    s->worst = fmi2OK;

/* When the host unloads this library, unload pythonfmu's with it: pythonfmu's own
 * library then lives exactly as long as it would in a host that loaded it directly. */
__attribute__((destructor)) static void unload_inner(void) {
    if (inner_lib && live_instances == 0) {
        dlclose(inner_lib);
        inner_lib = NULL;
    }
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Shim *s;
    if (!functions) return NULL;
    s = (Shim *)calloc(1, sizeof(Shim));
    if (!s) return NULL;
    s->host = *functions;
    s->wrapped = *functions;
    s->wrapped.logger = shim_logger;
    s->wrapped.componentEnvironment = s;
    s->debug_logging = loggingOn ? 1 : 0;
    s->name = strdup(instanceName ? instanceName : "");
    if (!load_inner()) {
        host_log(s, fmi2Error, "cannot load the FMU's pythonfmu library beside the shim");
        free(s->name);
        free(s);
        return NULL;
    }
    s->inner = INNER(fmi2Instantiate)(instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                      &s->wrapped, visible, fmi2True);
    if (!s->inner) {
        host_log(s, fmi2Error, "pythonfmu could not instantiate the model (see the message above)");
        free(s->name);
        free(s);
        return NULL;
    }
    live_instances++;
    return (fmi2Component)s;
}

void fmi2FreeInstance(fmi2Component c) {
    Shim *s = (Shim *)c;
    if (!s) return;
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
