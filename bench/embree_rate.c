/* Embree's own ray rate on rays captured from a render (bench/embree_rate.py writes them and
   builds this file against embreex's libembree4): closest hits one ray per call and in packets
   of 8 and 16, any hits one and 16 per call, on one thread; then 16-ray packets on 2 threads.
   Usage: embree_rate DIR NAME QUALITY (reads DIR/NAME.hdr, .v, .ray, .shadow). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <stdint.h>
#include <math.h>
#include <omp.h>
typedef void* RTCDevice; typedef void* RTCScene; typedef void* RTCGeometry;
RTCDevice rtcNewDevice(const char*); RTCScene rtcNewScene(RTCDevice);
void rtcSetSceneBuildQuality(RTCScene, int); void rtcSetSceneFlags(RTCScene, int);
RTCGeometry rtcNewGeometry(RTCDevice, int);
void* rtcSetNewGeometryBuffer(RTCGeometry, int, unsigned, int, size_t, size_t);
void rtcCommitGeometry(RTCGeometry); unsigned rtcAttachGeometry(RTCScene, RTCGeometry); void rtcCommitScene(RTCScene);
void rtcSetGeometryBuildQuality(RTCGeometry, int);
typedef struct __attribute__((aligned(16))) { float ox,oy,oz,tnear,dx,dy,dz,time,tfar; unsigned mask,id,flags;
  float ngx,ngy,ngz,u,v; unsigned primID, geomID, instID[1]; unsigned pad[8]; } RH1;
typedef struct __attribute__((aligned(64))) { float ox[16],oy[16],oz[16],tnear[16],dx[16],dy[16],dz[16],time[16],tfar[16];
  unsigned mask[16],id[16],flags[16]; float ngx[16],ngy[16],ngz[16],u[16],v[16]; unsigned primID[16],geomID[16],instID[16]; unsigned pad[64]; } RH16;
typedef struct __attribute__((aligned(32))) { float ox[8],oy[8],oz[8],tnear[8],dx[8],dy[8],dz[8],time[8],tfar[8];
  unsigned mask[8],id[8],flags[8]; float ngx[8],ngy[8],ngz[8],u[8],v[8]; unsigned primID[8],geomID[8],instID[8]; unsigned pad[32]; } RH8;
void rtcIntersect1(RTCScene, RH1*, void*); void rtcOccluded1(RTCScene, void*, void*);
void rtcIntersect16(const int*, RTCScene, RH16*, void*); void rtcOccluded16(const int*, RTCScene, void*, void*);
void rtcIntersect8(const int*, RTCScene, RH8*, void*);
static double now(){struct timespec t; clock_gettime(CLOCK_MONOTONIC,&t); return t.tv_sec+t.tv_nsec*1e-9;}
static void* rd(const char* p, size_t* n){FILE*f=fopen(p,"rb");fseek(f,0,SEEK_END);*n=ftell(f);fseek(f,0,SEEK_SET);void*b=malloc(*n);fread(b,1,*n,f);fclose(f);return b;}
int main(int argc, char** argv){
  char p[256]; size_t n; int quality = argc > 3 ? atoi(argv[3]) : 1;
  sprintf(p,"%s/%s.hdr",argv[1],argv[2]); int64_t* h=rd(p,&n);
  sprintf(p,"%s/%s.v",argv[1],argv[2]); float* v=rd(p,&n);
  sprintf(p,"%s/%s.ray",argv[1],argv[2]); float* r=rd(p,&n);
  sprintf(p,"%s/%s.shadow",argv[1],argv[2]); float* s=rd(p,&n);
  long nv=h[0], nr=h[1], ns=h[2];
  RTCDevice dev = rtcNewDevice("threads=2"); RTCScene sc = rtcNewScene(dev); rtcSetSceneBuildQuality(sc, quality);
  RTCGeometry g = rtcNewGeometry(dev, 0);
  float* vb = rtcSetNewGeometryBuffer(g, 1, 0, 0x9003, 12, nv); memcpy(vb, v, nv*12);
  unsigned* ib = rtcSetNewGeometryBuffer(g, 0, 0, 0x5003, 12, nv/3); for (long i=0;i<nv;i++) ib[i]=i;
  rtcSetGeometryBuildQuality(g, quality);
  rtcCommitGeometry(g); rtcAttachGeometry(sc,g); double tb=now(); rtcCommitScene(sc); tb=now()-tb;
  long hits=0; double best1=1e9, best16=1e9, besto=1e9, best8=1e9, besto16=1e9;
  for (int rep=0; rep<5; rep++){
    double t0=now(); hits=0;
    for (long i=0;i<nr;i++){ RH1 x; float*q=r+6*i; x.ox=q[0];x.oy=q[1];x.oz=q[2];x.tnear=0;x.dx=q[3];x.dy=q[4];x.dz=q[5];x.time=0;x.tfar=INFINITY;x.mask=-1;x.id=0;x.flags=0;x.geomID=-1;x.primID=-1;x.instID[0]=-1;
      rtcIntersect1(sc,&x,NULL); hits += x.geomID != (unsigned)-1; }
    double t1=now()-t0; if (t1<best1) best1=t1;
    t0=now(); long h16=0;
    for (long i=0;i<nr;i+=16){ RH16 x; int valid[16]; for(int k=0;k<16;k++){ long j=i+k; valid[k]= j<nr ? -1:0; float*q=r+6*(j<nr?j:0);
      x.ox[k]=q[0];x.oy[k]=q[1];x.oz[k]=q[2];x.tnear[k]=0;x.dx[k]=q[3];x.dy[k]=q[4];x.dz[k]=q[5];x.time[k]=0;x.tfar[k]=INFINITY;x.mask[k]=-1;x.id[k]=0;x.flags[k]=0;x.geomID[k]=-1;x.primID[k]=-1;x.instID[k]=-1;}
      rtcIntersect16(valid,sc,&x,NULL); for(int k=0;k<16;k++) h16 += valid[k] && x.geomID[k]!=(unsigned)-1; }
    t1=now()-t0; if (t1<best16) best16=t1; if (rep==0 && h16!=hits) printf("MISMATCH16 %ld %ld\n", h16, hits);
    t0=now(); long h8=0;
    for (long i=0;i<nr;i+=8){ RH8 x; int valid[8]; for(int k=0;k<8;k++){ long j=i+k; valid[k]= j<nr ? -1:0; float*q=r+6*(j<nr?j:0);
      x.ox[k]=q[0];x.oy[k]=q[1];x.oz[k]=q[2];x.tnear[k]=0;x.dx[k]=q[3];x.dy[k]=q[4];x.dz[k]=q[5];x.time[k]=0;x.tfar[k]=INFINITY;x.mask[k]=-1;x.id[k]=0;x.flags[k]=0;x.geomID[k]=-1;x.primID[k]=-1;x.instID[k]=-1;}
      rtcIntersect8(valid,sc,&x,NULL); for(int k=0;k<8;k++) h8 += valid[k] && x.geomID[k]!=(unsigned)-1; }
    t1=now()-t0; if (t1<best8) best8=t1;
    t0=now(); long occ=0;
    for (long i=0;i<ns;i++){ RH1 x; float*q=s+7*i; x.ox=q[0];x.oy=q[1];x.oz=q[2];x.tnear=0;x.dx=q[3];x.dy=q[4];x.dz=q[5];x.time=0;x.tfar=q[6];x.mask=-1;x.id=0;x.flags=0;
      rtcOccluded1(sc,&x,NULL); occ += x.tfar==-INFINITY; }
    t1=now()-t0; if (t1<besto) besto=t1;
    t0=now(); long occ16=0;
    for (long i=0;i<ns;i+=16){ RH16 x; int valid[16]; for(int k=0;k<16;k++){ long j=i+k; valid[k]= j<ns ? -1:0; float*q=s+7*(j<ns?j:0);
      x.ox[k]=q[0];x.oy[k]=q[1];x.oz[k]=q[2];x.tnear[k]=0;x.dx[k]=q[3];x.dy[k]=q[4];x.dz[k]=q[5];x.time[k]=0;x.tfar[k]=q[6];x.mask[k]=-1;x.id[k]=0;x.flags[k]=0;}
      rtcOccluded16(valid,sc,&x,NULL); for(int k=0;k<16;k++) occ16 += valid[k] && x.tfar[k]==-INFINITY; }
    t1=now()-t0; if (t1<besto16) besto16=t1;
  }
  double best_mt=1e9, best_mto=1e9;
  for (int rep=0; rep<5; rep++){
    double t0=now();
    #pragma omp parallel for schedule(dynamic, 64) num_threads(2)
    for (long i=0;i<nr;i+=16){ RH16 x; int valid[16]; for(int k=0;k<16;k++){ long j=i+k; valid[k]= j<nr ? -1:0; float*q=r+6*(j<nr?j:0);
      x.ox[k]=q[0];x.oy[k]=q[1];x.oz[k]=q[2];x.tnear[k]=0;x.dx[k]=q[3];x.dy[k]=q[4];x.dz[k]=q[5];x.time[k]=0;x.tfar[k]=INFINITY;x.mask[k]=-1;x.id[k]=0;x.flags[k]=0;x.geomID[k]=-1;x.primID[k]=-1;x.instID[k]=-1;}
      rtcIntersect16(valid,sc,&x,NULL); }
    double t1=now()-t0; if (t1<best_mt) best_mt=t1;
    t0=now();
    #pragma omp parallel for schedule(dynamic, 64) num_threads(2)
    for (long i=0;i<ns;i+=16){ RH16 x; int valid[16]; for(int k=0;k<16;k++){ long j=i+k; valid[k]= j<ns ? -1:0; float*q=s+7*(j<ns?j:0);
      x.ox[k]=q[0];x.oy[k]=q[1];x.oz[k]=q[2];x.tnear[k]=0;x.dx[k]=q[3];x.dy[k]=q[4];x.dz[k]=q[5];x.time[k]=0;x.tfar[k]=q[6];x.mask[k]=-1;x.id[k]=0;x.flags[k]=0;}
      rtcOccluded16(valid,sc,&x,NULL); }
    t1=now()-t0; if (t1<best_mto) best_mto=t1;
  }
  printf("  2 threads x16: intersect %.1f ns/ray wall, occluded %.1f ns/ray wall\n", best_mt/nr*1e9, best_mto/ns*1e9);
  printf("%s q%d: build %.3fs; intersect1 %.1f ns/ray (%.1f Mrays/s), x8 %.1f, x16 %.1f ns/ray; occluded1 %.1f ns/ray, x16 %.1f; %ld rays %ld hits, %ld shadow\n",
    argv[2], quality, tb, best1/nr*1e9, nr/best1/1e6, best8/nr*1e9, best16/nr*1e9, besto/ns*1e9, besto16/ns*1e9, nr, hits, ns);
}
