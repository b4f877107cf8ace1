/* nerfx: the interface between the host's C-variadic suite functions (param_shim.c) and the
 * typed Rust callbacks behind them (src/host/shim.rs). Written for this project: handles are
 * opaque pointers and statuses plain ints, so this header needs nothing from the OFX headers.
 */
#ifndef NERFX_SHIM_H
#define NERFX_SHIM_H

/* How a parameter's value travels through a va_list. */
enum nerfx_shim_kind {
    NERFX_KIND_NONE = 0,   /* group, page, push button: no value */
    NERFX_KIND_INT = 1,    /* integer, integer 2D/3D, boolean, choice: int (get: int *) */
    NERFX_KIND_DOUBLE = 2, /* double, double 2D/3D, RGB, RGBA: double (get: double *) */
    NERFX_KIND_STRING = 3  /* string, custom: const char * (get: const char **) */
};

/* What is asked of a parameter's value. */
enum nerfx_shim_query {
    NERFX_QUERY_VALUE = 0,      /* the value at time1 */
    NERFX_QUERY_DERIVATIVE = 1, /* d value / dt at time1 */
    NERFX_QUERY_INTEGRAL = 2    /* integral of the value over [time1, time2] */
};

/* The most components a parameter value has (RGBA). */
#define NERFX_SHIM_MAX_DIM 4

/* The Rust side, handed to the shim once by nerfx_shim_init. */
struct nerfx_shim_callbacks {
    /* The value shape of a parameter handle: kind and number of components. A handle the
     * host never gave out returns a non-zero status (and is recorded as a violation). */
    int (*param_shape)(void *param, int *kind, int *dim);
    /* Reads a value: doubles[dim] or ints[dim] or *string, per the parameter's kind. */
    int (*param_get)(void *param, int query, double time1, double time2, double *doubles,
                     int *ints, const char **string);
    /* Writes a value, at a time when has_time is non-zero. */
    int (*param_set)(void *param, int has_time, double time, const double *doubles,
                     const int *ints, const char *string);
    /* A message (already formatted), persistent or not. */
    int (*message)(void *handle, const char *type, const char *id, const char *text,
                   int persistent);
};

/* Installs the callbacks; called by the Rust side before any suite is handed out. */
void nerfx_shim_init(const struct nerfx_shim_callbacks *callbacks);

/* The variadic suite functions, with the signatures of the parameter and message suites. */
int nerfx_param_get_value(void *param, ...);
int nerfx_param_get_value_at_time(void *param, double time, ...);
int nerfx_param_get_derivative(void *param, double time, ...);
int nerfx_param_get_integral(void *param, double time1, double time2, ...);
int nerfx_param_set_value(void *param, ...);
int nerfx_param_set_value_at_time(void *param, double time, ...);
int nerfx_message(void *handle, const char *type, const char *id, const char *format, ...);
int nerfx_set_persistent_message(void *handle, const char *type, const char *id,
                                 const char *format, ...);

#endif
