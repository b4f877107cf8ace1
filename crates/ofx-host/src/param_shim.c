/* The host's C-variadic suite functions (parameter values and messages). Stable Rust cannot
 * define a C-variadic function, so these read their va_list according to the parameter's
 * shape, asked from Rust, and forward fixed-size arrays to typed Rust callbacks. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "nerfx_shim.h"

/* OFX status values this file returns itself (the OpenFX status codes). */
#define STATUS_OK 0
#define STATUS_FAILED 1
#define STATUS_ERR_MEMORY 8

static struct nerfx_shim_callbacks callbacks;
static int initialised;

void nerfx_shim_init(const struct nerfx_shim_callbacks *given)
{
    callbacks = *given;
    initialised = 1;
}

/* Reads a value into the caller's pointers, taken from the va_list. */
static int get(void *param, int query, double time1, double time2, va_list args)
{
    int kind = 0, dim = 0, i;
    double doubles[NERFX_SHIM_MAX_DIM] = {0};
    int ints[NERFX_SHIM_MAX_DIM] = {0};
    const char *string = NULL;
    int status;
    if (!initialised)
        return STATUS_FAILED;
    status = callbacks.param_shape(param, &kind, &dim);
    if (status != STATUS_OK)
        return status;
    if (dim < 0 || dim > NERFX_SHIM_MAX_DIM)
        return STATUS_FAILED;
    status = callbacks.param_get(param, query, time1, time2, doubles, ints, &string);
    if (status != STATUS_OK)
        return status;
    switch (kind) {
    case NERFX_KIND_INT:
        for (i = 0; i < dim; i++) {
            int *out = va_arg(args, int *);
            if (out)
                *out = ints[i];
        }
        break;
    case NERFX_KIND_DOUBLE:
        for (i = 0; i < dim; i++) {
            double *out = va_arg(args, double *);
            if (out)
                *out = doubles[i];
        }
        break;
    case NERFX_KIND_STRING: {
        const char **out = va_arg(args, const char **);
        if (out)
            *out = string;
        break;
    }
    default:
        return STATUS_FAILED;
    }
    return STATUS_OK;
}

/* Writes a value taken from the va_list. */
static int set(void *param, int has_time, double time, va_list args)
{
    int kind = 0, dim = 0, i;
    double doubles[NERFX_SHIM_MAX_DIM] = {0};
    int ints[NERFX_SHIM_MAX_DIM] = {0};
    const char *string = NULL;
    int status;
    if (!initialised)
        return STATUS_FAILED;
    status = callbacks.param_shape(param, &kind, &dim);
    if (status != STATUS_OK)
        return status;
    if (dim < 0 || dim > NERFX_SHIM_MAX_DIM)
        return STATUS_FAILED;
    switch (kind) {
    case NERFX_KIND_INT:
        for (i = 0; i < dim; i++)
            ints[i] = va_arg(args, int);
        break;
    case NERFX_KIND_DOUBLE:
        for (i = 0; i < dim; i++)
            doubles[i] = va_arg(args, double);
        break;
    case NERFX_KIND_STRING:
        string = va_arg(args, const char *);
        break;
    default:
        return STATUS_FAILED;
    }
    return callbacks.param_set(param, has_time, time, doubles, ints, string);
}

int nerfx_param_get_value(void *param, ...)
{
    va_list args;
    int status;
    va_start(args, param);
    status = get(param, NERFX_QUERY_VALUE, 0.0, 0.0, args);
    va_end(args);
    return status;
}

int nerfx_param_get_value_at_time(void *param, double time, ...)
{
    va_list args;
    int status;
    va_start(args, time);
    status = get(param, NERFX_QUERY_VALUE, time, time, args);
    va_end(args);
    return status;
}

int nerfx_param_get_derivative(void *param, double time, ...)
{
    va_list args;
    int status;
    va_start(args, time);
    status = get(param, NERFX_QUERY_DERIVATIVE, time, time, args);
    va_end(args);
    return status;
}

int nerfx_param_get_integral(void *param, double time1, double time2, ...)
{
    va_list args;
    int status;
    va_start(args, time2);
    status = get(param, NERFX_QUERY_INTEGRAL, time1, time2, args);
    va_end(args);
    return status;
}

int nerfx_param_set_value(void *param, ...)
{
    va_list args;
    int status;
    va_start(args, param);
    status = set(param, 0, 0.0, args);
    va_end(args);
    return status;
}

int nerfx_param_set_value_at_time(void *param, double time, ...)
{
    va_list args;
    int status;
    va_start(args, time);
    status = set(param, 1, time, args);
    va_end(args);
    return status;
}

/* Formats a printf-style message and hands it to Rust. */
static int post(void *handle, const char *type, const char *id, const char *format,
                int persistent, va_list args)
{
    va_list copy;
    int length, status;
    char *text;
    if (!initialised)
        return STATUS_FAILED;
    if (!format)
        return callbacks.message(handle, type, id, NULL, persistent);
    va_copy(copy, args);
    length = vsnprintf(NULL, 0, format, copy);
    va_end(copy);
    if (length < 0)
        return STATUS_FAILED;
    text = malloc((size_t)length + 1);
    if (!text)
        return STATUS_ERR_MEMORY;
    vsnprintf(text, (size_t)length + 1, format, args);
    status = callbacks.message(handle, type, id, text, persistent);
    free(text);
    return status;
}

int nerfx_message(void *handle, const char *type, const char *id, const char *format, ...)
{
    va_list args;
    int status;
    va_start(args, format);
    status = post(handle, type, id, format, 0, args);
    va_end(args);
    return status;
}

int nerfx_set_persistent_message(void *handle, const char *type, const char *id,
                                 const char *format, ...)
{
    va_list args;
    int status;
    va_start(args, format);
    status = post(handle, type, id, format, 1, args);
    va_end(args);
    return status;
}
