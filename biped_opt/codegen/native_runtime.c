/* The runtime a kernel library needs besides libc and libm (biped_opt/codegen/native.py).

   The kernel's machine code (Numba's, emitted as an object file with llvmlite) calls a few
   functions that Numba's own runtime provides when Numba loads the code. A library loaded
   without Numba gets them from here:

   - memory: the kernel's work arrays. An array's memory is one block, a header (its reference
     count, destructor, data pointer and size, in the order and widths of Numba's NRT_MemInfo,
     which the machine code reads and counts directly) followed by the data, aligned as asked.
   - errors: the kernel raises none itself (error_model "numpy", no bounds checks), so the only
     exceptions are Numba's own (an allocation that fails). Such a path counts itself in
     biped_opt_native_error_count and sets a Python error; the caller checks that count after
     every call and raises, so a failed call is never taken for a result.
   - the interpreter lock, which the error path takes to report.

   Nothing here includes Python's headers: the few functions of its C API are declared below,
   and resolved at load time from the running interpreter. */

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef void (*biped_opt_dtor)(void *data, size_t size, void *info);

/* Numba's NRT_MemInfo (numba/core/runtime/nrt.cpp): six machine words, in this order */
typedef struct {
    atomic_size_t refct;
    biped_opt_dtor dtor;
    void *dtor_info;
    void *data;
    size_t size;
    void *external_allocator;
} biped_opt_meminfo;

/* the Python C API the error path uses (an int stands for PyGILState_STATE, an enum) */
extern int PyGILState_Ensure(void);
extern void PyGILState_Release(int);
extern void *PyExc_RuntimeError;
extern void PyErr_SetString(void *type, const char *message);
extern void *PyErr_Occurred(void);

/* how many calls took the error path (read in place by the caller, before and after a call) */
atomic_long biped_opt_native_error_count = 0;

static void count_error(void) {
    atomic_fetch_add(&biped_opt_native_error_count, 1);
    if (PyErr_Occurred() == NULL)
        PyErr_SetString(PyExc_RuntimeError,
                        "biped_opt: the compiled kernel failed (see biped_opt_native_error_count)");
}

biped_opt_meminfo *NRT_MemInfo_alloc_aligned(size_t size, unsigned align) {
    if (align == 0)
        align = 1;
    size_t header = sizeof(biped_opt_meminfo);
    char *base = malloc(header + size + 2 * (size_t)align);
    if (base == NULL)
        return NULL;
    uintptr_t start = (uintptr_t)(base + header);
    uintptr_t rem = start % align;
    biped_opt_meminfo *mi = (biped_opt_meminfo *)base;
    atomic_init(&mi->refct, 1);
    mi->dtor = NULL;
    mi->dtor_info = NULL;
    mi->data = (void *)(rem ? start + (align - rem) : start);
    mi->size = size;
    mi->external_allocator = NULL;
    return mi;
}

void NRT_MemInfo_call_dtor(biped_opt_meminfo *mi) {
    if (mi->dtor != NULL)
        mi->dtor(mi->data, mi->size, mi->dtor_info);
    free(mi);
}

void NRT_Free(void *ptr) { free(ptr); }

int numba_gil_ensure(void) { return PyGILState_Ensure(); }

void numba_gil_release(int state) { PyGILState_Release(state); }

/* Numba's exception path: build the exception (from its pickled description), raise it. Here
   it is counted and reported as a RuntimeError (see above). */
void *numba_unpickle(const char *data, int n, const char *hashed) {
    (void)data; (void)n; (void)hashed;
    count_error();
    return NULL;
}

void *numba_runtime_build_excinfo_struct(void *info, void *args) {
    (void)info; (void)args;
    count_error();
    return NULL;
}

int numba_do_raise(void *exc) {
    (void)exc;
    count_error();
    return 0;
}
