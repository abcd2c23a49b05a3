/* LD_PRELOAD shim: counts malloc/calloc/realloc/memalign calls. chaincompd looks up
 * chaincomp_alloc_count() with dlsym and reports the allocations made after start-up. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stddef.h>
#include <stdatomic.h>

static atomic_llong g_count;
static void* (*real_malloc)(size_t);
static void* (*real_calloc)(size_t, size_t);
static void* (*real_realloc)(void*, size_t);
static int (*real_posix_memalign)(void**, size_t, size_t);

/* dlsym may call calloc before real_calloc is known: serve it from a static pool. */
static char g_pool[4096];
static size_t g_pool_used;

long long chaincomp_alloc_count(void) { return atomic_load(&g_count); }

void* malloc(size_t n) {
  if (!real_malloc) real_malloc = (void* (*)(size_t))dlsym(RTLD_NEXT, "malloc");
  atomic_fetch_add(&g_count, 1);
  return real_malloc(n);
}

void* calloc(size_t a, size_t b) {
  if (!real_calloc) {
    static int resolving;
    if (resolving) {
      size_t n = (a * b + 15) & ~(size_t)15;
      if (g_pool_used + n > sizeof g_pool) return NULL;
      void* p = g_pool + g_pool_used;
      g_pool_used += n;
      return p;
    }
    resolving = 1;
    real_calloc = (void* (*)(size_t, size_t))dlsym(RTLD_NEXT, "calloc");
    resolving = 0;
  }
  atomic_fetch_add(&g_count, 1);
  return real_calloc(a, b);
}

void* realloc(void* p, size_t n) {
  if (!real_realloc) real_realloc = (void* (*)(void*, size_t))dlsym(RTLD_NEXT, "realloc");
  atomic_fetch_add(&g_count, 1);
  return real_realloc(p, n);
}

int posix_memalign(void** p, size_t a, size_t n) {
  if (!real_posix_memalign) real_posix_memalign = (int (*)(void**, size_t, size_t))dlsym(RTLD_NEXT, "posix_memalign");
  atomic_fetch_add(&g_count, 1);
  return real_posix_memalign(p, a, n);
}
