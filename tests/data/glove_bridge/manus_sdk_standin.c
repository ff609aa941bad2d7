/* A stand-in for the MANUS SDK's shared library (libManusSDK_Integrated.so / libManusSDK.so), for the glove bridge's
 * tests: the functions manus_bridge.py calls, with the signatures of MANUS's public ManusSDK.h and the struct layouts
 * of ManusSDKTypes.h, returning recorded hand data.
 *
 * It keeps the SDK's rules that a client can get wrong: nothing works before CoreSdk_Initialize*, ConnectToHost
 * refuses without a coordinate system (SDKReturnCode_NoCoordinateSystemSet), a host list must be read with its exact
 * count (SDKReturnCode_ArgumentSizeMismatch), and the landscape does not know a glove yet when first
 * asked (SDKReturnCode_DataNotAvailable). After ConnectToHost a thread of its own calls the ergonomics callback
 * every 10 ms with the recorded streams of standin_frames.h (written by the test), then repeats the last one until
 * ShutDown.
 * $STANDIN_DISCONNECT_AT=<n>: after n streams it reports a disconnect once (the dongle unplugged) and streams on.
 * Every call is appended to $STANDIN_LOG; $STANDIN_FAIL=<function>=<code> makes that function return <code>. */
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef int SDKReturnCode; /* enum SDKReturnCode: 0 Success, 5 SdkNotAvailable, 7 DataNotAvailable, ... */
typedef struct ManusTimestamp { uint64_t time; } ManusTimestamp;
typedef struct ErgonomicsData { uint32_t id; bool isUserID; float data[40]; } ErgonomicsData;
typedef struct ErgonomicsStream {
  ManusTimestamp publishTime;
  ErgonomicsData data[32]; /* MAX_NUMBER_OF_ERGONOMICS_DATA */
  uint32_t dataCount;
} ErgonomicsStream;
typedef struct Version { uint32_t major, minor, patch; char label[16], sha[16], tag[16]; } Version;
typedef struct ManusHost { char hostName[256]; char ipAddress[40]; Version manusCoreVersion; } ManusHost;
typedef struct CoordinateSystemVUH { int view; int up; int handedness; float unitScale; } CoordinateSystemVUH;
typedef struct IMUCalibrationInfo { uint32_t mag, acc, gyr, sys; } IMUCalibrationInfo;
typedef struct GloveLandscapeData {
  uint32_t id; int classType; int familyType; int side; bool isHaptics; int pairedState; uint32_t dongleID;
  Version hardwareVersion; Version firmwareVersion; ManusTimestamp firmwareTimestamp; int updateStatus;
  uint32_t batteryPercentage; int32_t transmissionStrength; IMUCalibrationInfo iMUCalibrationInfo[6];
  ManusTimestamp lastSeen; bool excluded; uint32_t netDeviceID;
} GloveLandscapeData;
typedef void (*ErgonomicsStreamCallback_t)(const ErgonomicsStream* const);
typedef void (*ConnectedToCoreCallback_t)(const ManusHost* const);
typedef void (*DisconnectedFromCoreCallback_t)(const ManusHost* const);

/* N_STREAMS, ENTRIES, STREAMS[N_STREAMS][ENTRIES] = {glove or user id, is user id, 40 values}; N_GLOVES,
 * GLOVES[] = {id, side (1 Side_Left, 2 Side_Right)}; N_HOSTS, HOSTS[] = {name, ip}. */
#include "standin_frames.h"

static pthread_mutex_t g_mu = PTHREAD_MUTEX_INITIALIZER;
static ErgonomicsStreamCallback_t g_ergonomics;
static ConnectedToCoreCallback_t g_on_connect;
static DisconnectedFromCoreCallback_t g_on_disconnect;
static bool g_initialized, g_coordinates, g_stop, g_looked;
static pthread_t g_thread;
static bool g_thread_running;

static void say(const char* fmt, const char* arg) {
  const char* path = getenv("STANDIN_LOG");
  FILE* f = path ? fopen(path, "a") : NULL;
  if (!f) return;
  fprintf(f, fmt, arg);
  fputc('\n', f);
  fclose(f);
}

static SDKReturnCode gate(const char* name, bool needs_init) {
  say("%s", name);
  const char* fail = getenv("STANDIN_FAIL");
  size_t n = strlen(name);
  if (fail && strncmp(fail, name, n) == 0 && fail[n] == '=') return atoi(fail + n + 1);
  return needs_init && !g_initialized ? 5 /* SdkNotAvailable */ : 0;
}

#define GATE(needs_init)                       \
  do {                                         \
    SDKReturnCode rc = gate(__func__, needs_init); \
    if (rc) return rc;                         \
  } while (0)

SDKReturnCode CoreSdk_InitializeIntegrated(void) { GATE(false); g_initialized = true; return 0; }
SDKReturnCode CoreSdk_InitializeCore(void) { GATE(false); g_initialized = true; return 0; }

SDKReturnCode CoreSdk_RegisterCallbackForErgonomicsStream(ErgonomicsStreamCallback_t cb) {
  GATE(true);
  say("  callback %s", cb ? "set" : "NULL");
  pthread_mutex_lock(&g_mu);
  g_ergonomics = cb;
  pthread_mutex_unlock(&g_mu);
  return 0;
}
SDKReturnCode CoreSdk_RegisterCallbackForOnConnect(ConnectedToCoreCallback_t cb) {
  GATE(true); say("  callback %s", cb ? "set" : "NULL"); g_on_connect = cb; return 0;
}
SDKReturnCode CoreSdk_RegisterCallbackForOnDisconnect(DisconnectedFromCoreCallback_t cb) {
  GATE(true); say("  callback %s", cb ? "set" : "NULL"); g_on_disconnect = cb; return 0;
}

SDKReturnCode CoreSdk_InitializeCoordinateSystemWithVUH(CoordinateSystemVUH cs, bool world) {
  GATE(true);
  char buf[96];
  snprintf(buf, sizeof buf, "view=%d up=%d handedness=%d scale=%g world=%d", cs.view, cs.up, cs.handedness,
           (double)cs.unitScale, (int)world);
  say("  %s", buf);
  g_coordinates = true;
  return 0;
}

SDKReturnCode CoreSdk_LookForHosts(uint32_t wait_seconds, bool loopback_only) {
  GATE(true); (void)wait_seconds; (void)loopback_only; g_looked = true; return 0;
}
SDKReturnCode CoreSdk_GetNumberOfAvailableHostsFound(uint32_t* n) {
  GATE(true); *n = g_looked ? N_HOSTS : 0; return 0;
}
SDKReturnCode CoreSdk_GetAvailableHostsFound(ManusHost* hosts, const uint32_t n) {
  GATE(true);
  if (!g_looked || n != N_HOSTS) return 3; /* ArgumentSizeMismatch */
  for (uint32_t i = 0; i < n; i++) {
    memset(&hosts[i], 0, sizeof hosts[i]);
    snprintf(hosts[i].hostName, sizeof hosts[i].hostName, "%s", HOSTS[i][0]);
    snprintf(hosts[i].ipAddress, sizeof hosts[i].ipAddress, "%s", HOSTS[i][1]);
  }
  return 0;
}

static void* stream_thread(void* arg) {
  (void)arg;
  static ErgonomicsStream s;
  const char* drop = getenv("STANDIN_DISCONNECT_AT"); /* after that many streams, report one disconnect */
  int drop_at = drop ? atoi(drop) : -1;
  struct timespec tick = {0, 10 * 1000 * 1000};
  for (int k = 0;; k++) {
    int i = k < N_STREAMS ? k : N_STREAMS - 1;
    memset(&s, 0, sizeof s);
    s.publishTime.time = (uint64_t)k;
    s.dataCount = ENTRIES;
    for (int e = 0; e < ENTRIES; e++) {
      s.data[e].id = STREAMS[i][e].id;
      s.data[e].isUserID = STREAMS[i][e].user;
      memcpy(s.data[e].data, STREAMS[i][e].v, sizeof s.data[e].data);
    }
    pthread_mutex_lock(&g_mu);
    bool stop = g_stop;
    if (!stop && g_ergonomics) g_ergonomics(&s);
    pthread_mutex_unlock(&g_mu);
    if (stop) return NULL;
    if (k + 1 == drop_at && g_on_disconnect) {
      static ManusHost gone;
      say("  %s", "disconnected");
      g_on_disconnect(&gone);
    }
    nanosleep(&tick, NULL);
  }
}

void ManusHost_Init(ManusHost* host) { /* ManusSDKTypeInitializers.h */
  say("%s", "ManusHost_Init");
  memset(host, 0, sizeof *host);
}

SDKReturnCode CoreSdk_ConnectToHost(ManusHost host) {
  GATE(true);
  say("  host '%s'", host.hostName[0] ? host.hostName : host.ipAddress);
  if (!g_coordinates) return 16; /* NoCoordinateSystemSet */
  if (g_on_connect) g_on_connect(&host);
  if (!g_thread_running) g_thread_running = pthread_create(&g_thread, NULL, stream_thread, NULL) == 0;
  return 0;
}

SDKReturnCode CoreSdk_GetDataForGlove_UsingGloveId(uint32_t id, GloveLandscapeData* out) {
  GATE(true);
  static int asked;
  if (asked++ == 0) { /* the landscape lags the first stream: the first question is always too early */
    say("  %s", "not in the landscape yet");
    return 7;
  }
  for (int i = 0; i < N_GLOVES; i++) {
    if (GLOVES[i][0] == id) {
      memset(out, 0, sizeof *out);
      out->id = id;
      out->classType = 2; /* DeviceClassType_Glove */
      out->side = (int)GLOVES[i][1];
      return 0;
    }
  }
  return 7; /* DataNotAvailable: not in the landscape */
}

SDKReturnCode CoreSdk_ShutDown(void) {
  GATE(true);
  pthread_mutex_lock(&g_mu);
  g_stop = true;
  bool live_callback = g_ergonomics != NULL;
  pthread_mutex_unlock(&g_mu);
  if (g_thread_running) pthread_join(g_thread, NULL);
  g_thread_running = false;
  g_initialized = false;
  say("  shut down with the ergonomics callback %s", live_callback ? "still set" : "unregistered");
  return 0;
}
