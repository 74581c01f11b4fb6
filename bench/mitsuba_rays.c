/* Counts the rays Mitsuba 3 hands its Embree: preloaded (LD_PRELOAD) into a process that renders
   with Mitsuba, it stands in for the packet entry points of Mitsuba's namespaced libembree3
   (mitsuba::rtcIntersect{1,4,8,16}, mitsuba::rtcOccluded{1,4,8,16}), counts each call, its active
   lanes (valid != 0) and whether the context asks for coherent traversal, and forwards the call to
   the real function, found in the library $MITSUBA_EMBREE (Mitsuba loads it with its module, out of
   the global namespace). At exit it writes one line of JSON to $MITSUBA_RAYS_OUT
   (bench/mitsuba_rays.py builds this file and reads that line). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

typedef void (*packet_fn)(const int *, void *, void *, void *);
typedef void (*single_fn)(void *, void *, void *);

/* calls, active lanes and coherent calls, per entry point: intersect 1, 4, 8, 16, occluded 1, 4, 8, 16 */
static long calls[8], lanes[8], coherent[8];

static void *real(const char *name) {
  static void *lib;
  if (!lib) lib = dlopen(getenv("MITSUBA_EMBREE"), RTLD_LAZY);
  void *f = lib ? dlsym(lib, name) : NULL;
  if (!f) {
    fprintf(stderr, "mitsuba_rays: %s not found\n", name);
    abort();
  }
  return f;
}

/* the context's first field is its flags (RTC_INTERSECT_CONTEXT_FLAG_COHERENT = 1) */
static void count(int slot, const int *valid, int width, void *ctx) {
  int on = 0;
  for (int k = 0; k < width; k++) on += valid == NULL || valid[k] != 0;
  __atomic_add_fetch(&calls[slot], 1, __ATOMIC_RELAXED);
  __atomic_add_fetch(&lanes[slot], on, __ATOMIC_RELAXED);
  if (ctx && (*(const int *)ctx & 1)) __atomic_add_fetch(&coherent[slot], 1, __ATOMIC_RELAXED);
}

#define PACKET(fname, sym, slot, width)                                            \
  void fname(const int *valid, void *scene, void *ctx, void *ray) __asm__(sym);   \
  void fname(const int *valid, void *scene, void *ctx, void *ray) {               \
    static packet_fn f;                                                            \
    if (!f) f = (packet_fn)real(sym);                                              \
    count(slot, valid, width, ctx);                                                \
    f(valid, scene, ctx, ray);                                                     \
  }
#define SINGLE(fname, sym, slot)                                                   \
  void fname(void *scene, void *ctx, void *ray) __asm__(sym);                     \
  void fname(void *scene, void *ctx, void *ray) {                                  \
    static single_fn f;                                                            \
    if (!f) f = (single_fn)real(sym);                                              \
    count(slot, NULL, 1, ctx);                                                     \
    f(scene, ctx, ray);                                                            \
  }

SINGLE(i1, "_ZN7mitsuba13rtcIntersect1EPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_9RTCRayHitE", 0)
PACKET(i4, "_ZN7mitsuba13rtcIntersect4EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_10RTCRayHit4E", 1, 4)
PACKET(i8, "_ZN7mitsuba13rtcIntersect8EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_10RTCRayHit8E", 2, 8)
PACKET(i16, "_ZN7mitsuba14rtcIntersect16EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_11RTCRayHit16E", 3, 16)
SINGLE(o1, "_ZN7mitsuba12rtcOccluded1EPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_6RTCRayE", 4)
PACKET(o4, "_ZN7mitsuba12rtcOccluded4EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_7RTCRay4E", 5, 4)
PACKET(o8, "_ZN7mitsuba12rtcOccluded8EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_7RTCRay8E", 6, 8)
PACKET(o16, "_ZN7mitsuba13rtcOccluded16EPKiPNS_10RTCSceneTyEPNS_19RTCIntersectContextEPNS_8RTCRay16E", 7, 16)

__attribute__((destructor)) static void report(void) {
  const char *path = getenv("MITSUBA_RAYS_OUT");
  FILE *f = path ? fopen(path, "w") : stderr;
  if (!f) return;
  static const char *names[8] = {"intersect1", "intersect4", "intersect8", "intersect16",
                                 "occluded1", "occluded4", "occluded8", "occluded16"};
  fprintf(f, "{");
  for (int s = 0; s < 8; s++)
    fprintf(f, "%s\"%s\": [%ld, %ld, %ld]", s ? ", " : "", names[s], calls[s], lanes[s], coherent[s]);
  fprintf(f, "}\n");
  if (path) fclose(f);
}
