// octolinear-oracle: a small C ABI over the system OctoMap library (octomap::OcTree).
//
// This is test-only glue.  Every function is `extern "C"`, never lets a C++
// exception escape (they are caught and turned into an error status), and
// validates the arguments for which the Debian build of OctoMap (assertions
// enabled) would otherwise abort the whole process: tree depths above 16 and
// rays that would overflow the fixed-size `KeyRay` (100000 keys).
//
// Conventions
//   * Status-returning functions return OLO_OK (0) on success, a negative
//     OLO_E* code on failure.
//   * Variable-length results are returned as malloc'ed arrays plus a count;
//     the caller frees them with olo_free().  A zero-length result may be NULL.
//   * Points are float[3] (octomap::point3d), keys uint16_t[3].

// Keep OctoMap's OCTOMAP_DEBUG chatter (compiled into this translation unit
// through the templates) out.  Its warnings and errors go where
// olo_route_output sends them.
#define OCTOMAP_NODEBUGOUT 1

#include <octomap/octomap.h>
#include <octomap/OcTree.h>
#include <octomap/AbstractOcTree.h>
#include <octomap/ColorOcTree.h>
#include <octomap/MapCollection.h>
#include <octomap/OcTreeStamped.h>

#include <ctime>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <limits>
#include <new>
#include <sstream>
#include <streambuf>
#include <string>
#include <vector>

using octomap::OcTree;
using octomap::OcTreeKey;
using octomap::OcTreeNode;
using octomap::point3d;

namespace {

enum {
  OLO_OK = 0,
  OLO_EINVAL = -1,        // invalid argument (depth > 16, null pointer, ...)
  OLO_ERAY_TOO_LONG = -2, // a ray would overflow OctoMap's KeyRay (assert / overflow)
  OLO_EFAILED = -3,       // OctoMap reported failure (e.g. write returned false)
  OLO_EEXCEPTION = -4,    // a C++ exception was caught
};

// Rays whose endpoints are further apart than this (L1 distance in keys) are
// refused.  computeRayKeys adds at most one key per step and stops at the end
// key, so the number of keys is bounded by the L1 distance (+1 for the origin);
// OctoMap asserts `ray.size() < 100000 - 1`.  Keep a generous margin.
const long kMaxRayL1 = 99000;

}  // namespace

struct OloTree {
  OcTree* tree;
  octomap::KeyRay ray;  // scratch ray for computeRayKeys (100000 keys; allocate once)
  explicit OloTree(OcTree* t) : tree(t) {}
  ~OloTree() { delete tree; }
};

// Layouts mirrored in Rust (#[repr(C)]).
struct OloNode {
  uint16_t key[3];
  uint8_t depth;
  uint8_t is_leaf;
  float logodds;
};

struct OloChange {
  uint16_t key[3];
  uint8_t is_new;
  uint8_t pad;
};

struct OloStats {
  uint64_t size;
  uint64_t num_leaf_nodes;
  uint64_t calc_num_nodes;
  uint64_t memory_usage;
  uint64_t memory_usage_node;
  uint64_t memory_full_grid;
  uint64_t num_changes_detected;
  double resolution;
  uint32_t tree_depth;
  uint32_t has_root;
  float root_logodds;
  float pad;
  double metric_min[3];        // non-const getMetricMin
  double metric_max[3];        // non-const getMetricMax
  double metric_size[3];       // non-const getMetricSize
  double const_metric_min[3];  // const overloads
  double const_metric_max[3];
  double const_metric_size[3];
  double volume;
};

struct OloSensor {
  double clamp_min, clamp_max, prob_hit, prob_miss, occupancy_thres;  // probabilities
  float clamp_min_log, clamp_max_log, prob_hit_log, prob_miss_log, occupancy_thres_log;
};

#define OLO_TRY try {
#define OLO_CATCH(ret)                 \
  }                                    \
  catch (...) {                        \
    return ret;                        \
  }

namespace {

inline point3d P(const float* p) { return point3d(p[0], p[1], p[2]); }
inline void put(float* out, const point3d& p) {
  out[0] = p.x();
  out[1] = p.y();
  out[2] = p.z();
}
inline OcTreeKey K(const uint16_t* k) { return OcTreeKey(k[0], k[1], k[2]); }

bool valid_depth(unsigned depth) { return depth <= 16; }

// Would computeRayKeys(origin, end) be safe w.r.t. the KeyRay capacity?
// If either endpoint is outside the map computeRayKeys returns false early,
// which is safe too.
template <class TREE>
bool ray_ok(const TREE* t, const point3d& origin, const point3d& end) {
  OcTreeKey ko, ke;
  if (!t->coordToKeyChecked(origin, ko) || !t->coordToKeyChecked(end, ke)) return true;
  long l1 = 0;
  for (int i = 0; i < 3; ++i) l1 += std::labs((long)ko[i] - (long)ke[i]);
  return l1 <= kMaxRayL1;
}

// Replicates the ray endpoints insertPointCloud would trace (computeUpdate /
// computeDiscreteUpdate) and checks each against the KeyRay capacity.
template <class TREE>
bool cloud_ok(const TREE* t, const octomap::Pointcloud& pc, const point3d& origin, double maxrange,
              bool discretize) {
  for (size_t i = 0; i < pc.size(); ++i) {
    point3d p = pc[i];
    if (discretize) p = t->keyToCoord(t->coordToKey(p));
    point3d end = p;
    if (!(maxrange < 0.0) && !((p - origin).norm() <= maxrange)) {
      point3d dir = (p - origin).normalized();
      end = origin + dir * (float)maxrange;
    }
    if (!ray_ok(t, origin, end)) return false;
  }
  return true;
}

void fill_cloud(octomap::Pointcloud& pc, const float* xyz, size_t n) {
  pc.reserve(n);
  for (size_t i = 0; i < n; ++i) pc.push_back(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
}

template <class T>
T* to_malloc(const std::vector<T>& v) {
  if (v.empty()) return nullptr;
  T* p = static_cast<T*>(std::malloc(v.size() * sizeof(T)));
  if (!p) throw std::bad_alloc();
  std::memcpy(p, v.data(), v.size() * sizeof(T));
  return p;
}

int stream_out(const std::string& s, uint8_t** out, size_t* out_len) {
  *out = nullptr;
  *out_len = s.size();
  if (s.empty()) return OLO_OK;
  *out = static_cast<uint8_t*>(std::malloc(s.size()));
  if (!*out) return OLO_EEXCEPTION;
  std::memcpy(*out, s.data(), s.size());
  return OLO_OK;
}

void set_sensor(OcTree* t, double cmin, double cmax, double hit, double miss) {
  // Same order as OctoMap's graph2tree tool.
  t->setClampingThresMin(cmin);
  t->setClampingThresMax(cmax);
  t->setProbHit(hit);
  t->setProbMiss(miss);
}

}  // namespace

// ---------------------------------------------------------------- console output
//
// OctoMap reports on the console four ways: printf and fprintf on the C
// streams stdout and stderr (OCTOMAP_WARNING, MapCollection's per-ray lines,
// also from inside liboctomap) and std::cout / std::cerr
// (OCTOMAP_ERROR_STR, "Reading binary octree ...").  olo_route_output points
// all four at a callback, unbuffered, so that every piece of text is handed
// over on the thread that wrote it.

typedef void (*OloWriteFn)(int stream, const char* data, size_t len);

namespace {

OloWriteFn g_write = nullptr;

// A std::streambuf without a buffer: every character goes to g_write at once,
// so it keeps no state that threads writing at the same time could share.
class CallbackBuf : public std::streambuf {
 public:
  explicit CallbackBuf(int stream) : stream_(stream) {}

 protected:
  int_type overflow(int_type c) override {
    if (!traits_type::eq_int_type(c, traits_type::eof())) {
      char ch = traits_type::to_char_type(c);
      g_write(stream_, &ch, 1);
    }
    return traits_type::not_eof(c);
  }
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    g_write(stream_, s, static_cast<size_t>(n));
    return n;
  }

 private:
  int stream_;
};

#if defined(__GLIBC__)
// fopencookie write function; the cookie is the stream number (1 or 2).
ssize_t cookie_write(void* cookie, const char* buf, size_t size) {
  g_write(static_cast<int>(reinterpret_cast<intptr_t>(cookie)), buf, size);
  return static_cast<ssize_t>(size);
}
#endif

}  // namespace

extern "C" {

// Sends everything OctoMap writes to stdout (stream 1) or stderr (stream 2)
// to `write` from now on, for the rest of the process.  Call it once, before
// any other shim function.  OLO_EFAILED (nothing changed) where the C
// library cannot make a stream of a callback (fopencookie is glibc's).
int olo_route_output(OloWriteFn write) {
#if defined(__GLIBC__)
  cookie_io_functions_t io = {nullptr, cookie_write, nullptr, nullptr};
  FILE* out = fopencookie(reinterpret_cast<void*>(1), "w", io);
  FILE* err = fopencookie(reinterpret_cast<void*>(2), "w", io);
  if (!out || !err || setvbuf(out, nullptr, _IONBF, 0) != 0 || setvbuf(err, nullptr, _IONBF, 0) != 0) {
    if (out) fclose(out);
    if (err) fclose(err);
    return OLO_EFAILED;
  }
  g_write = write;
  std::fflush(stdout);
  std::fflush(stderr);
  // glibc documents stdout and stderr as ordinary variables one may assign.
  stdout = out;
  stderr = err;
  static CallbackBuf out_buf(1), err_buf(2);
  std::cout.rdbuf(&out_buf);
  std::cerr.rdbuf(&err_buf);
  std::clog.rdbuf(&err_buf);
  return OLO_OK;
#else
  (void)write;
  return OLO_EFAILED;
#endif
}

void olo_free(void* p) { std::free(p); }

// ---------------------------------------------------------------- lifecycle

OloTree* olo_tree_new(double resolution) {
  OLO_TRY
  OcTree* t = new OcTree(resolution);
  return new OloTree(t);
  OLO_CATCH(nullptr)
}

// setClampingThresMin, setClampingThresMax, setProbHit, setProbMiss (graph2tree order).
// The caller guarantees prob_hit >= 0.5 and prob_miss <= 0.5 (OctoMap asserts).
OloTree* olo_tree_new_sensor(double resolution, double clamp_min, double clamp_max, double prob_hit,
                             double prob_miss) {
  OLO_TRY
  OcTree* t = new OcTree(resolution);
  OloTree* h = new OloTree(t);
  set_sensor(t, clamp_min, clamp_max, prob_hit, prob_miss);
  return h;
  OLO_CATCH(nullptr)
}

// Exactly what the golden harness calls "default": read the probabilities back
// from the fresh tree and set them again in graph2tree order.
OloTree* olo_tree_new_graph2tree_default(double resolution) {
  OLO_TRY
  OcTree* t = new OcTree(resolution);
  OloTree* h = new OloTree(t);
  double cmin = t->getClampingThresMin(), cmax = t->getClampingThresMax();
  double hit = t->getProbHit(), miss = t->getProbMiss();
  set_sensor(t, cmin, cmax, hit, miss);
  return h;
  OLO_CATCH(nullptr)
}

void olo_tree_free(OloTree* h) { delete h; }

int olo_set_sensor(OloTree* h, double clamp_min, double clamp_max, double prob_hit, double prob_miss) {
  OLO_TRY
  set_sensor(h->tree, clamp_min, clamp_max, prob_hit, prob_miss);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_set_occupancy_thres(OloTree* h, double p) {
  OLO_TRY
  h->tree->setOccupancyThres(p);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

void olo_get_sensor(const OloTree* h, OloSensor* out) {
  const OcTree* t = h->tree;
  out->clamp_min = t->getClampingThresMin();
  out->clamp_max = t->getClampingThresMax();
  out->prob_hit = t->getProbHit();
  out->prob_miss = t->getProbMiss();
  out->occupancy_thres = t->getOccupancyThres();
  out->clamp_min_log = t->getClampingThresMinLog();
  out->clamp_max_log = t->getClampingThresMaxLog();
  out->prob_hit_log = t->getProbHitLog();
  out->prob_miss_log = t->getProbMissLog();
  out->occupancy_thres_log = t->getOccupancyThresLog();
}

int olo_set_bbx(OloTree* h, const float* min, const float* max) {
  OLO_TRY
  point3d a = P(min), b = P(max);
  h->tree->setBBXMin(a);
  h->tree->setBBXMax(b);
  h->tree->useBBXLimit(true);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

void olo_use_bbx_limit(OloTree* h, int enable) { h->tree->useBBXLimit(enable != 0); }

void olo_enable_change_detection(OloTree* h, int enable) { h->tree->enableChangeDetection(enable != 0); }

void olo_reset_change_detection(OloTree* h) { h->tree->resetChangeDetection(); }

// ---------------------------------------------------------------- updates

int olo_insert_point_cloud(OloTree* h, const float* xyz, size_t n, const float* origin, double maxrange,
                           int lazy_eval, int discretize) {
  OLO_TRY
  octomap::Pointcloud pc;
  fill_cloud(pc, xyz, n);
  point3d o = P(origin);
  if (!cloud_ok(h->tree, pc, o, maxrange, discretize != 0)) return OLO_ERAY_TOO_LONG;
  h->tree->insertPointCloud(pc, o, maxrange, lazy_eval != 0, discretize != 0);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_insert_point_cloud_rays(OloTree* h, const float* xyz, size_t n, const float* origin, double maxrange,
                                int lazy_eval) {
  OLO_TRY
  octomap::Pointcloud pc;
  fill_cloud(pc, xyz, n);
  point3d o = P(origin);
  // insertPointCloudRays ignores maxrange and traces every ray to its endpoint.
  if (!cloud_ok(h->tree, pc, o, -1.0, false)) return OLO_ERAY_TOO_LONG;
  h->tree->insertPointCloudRays(pc, o, maxrange, lazy_eval != 0);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// Inserts n_scans scans back to back (loop inside C++ for benchmarking).
// Scan i has counts[i] points, taken consecutively from xyz; origins is 3*n_scans.
// If lazy_eval, updateInnerOccupancy() is called after every scan (like the golden harness).
int olo_insert_scans(OloTree* h, const float* xyz, const size_t* counts, const float* origins, size_t n_scans,
                     double maxrange, int lazy_eval, int discretize) {
  OLO_TRY
  std::vector<octomap::Pointcloud> clouds(n_scans);
  size_t off = 0;
  for (size_t s = 0; s < n_scans; ++s) {
    fill_cloud(clouds[s], xyz + 3 * off, counts[s]);
    off += counts[s];
    if (!cloud_ok(h->tree, clouds[s], P(origins + 3 * s), maxrange, discretize != 0)) return OLO_ERAY_TOO_LONG;
  }
  for (size_t s = 0; s < n_scans; ++s) {
    h->tree->insertPointCloud(clouds[s], P(origins + 3 * s), maxrange, lazy_eval != 0, discretize != 0);
    if (lazy_eval) h->tree->updateInnerOccupancy();
  }
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_update_inner_occupancy(OloTree* h) {
  OLO_TRY
  h->tree->updateInnerOccupancy();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// Returns 1 if a node was updated (non-NULL), 0 if the point is outside the map.
int olo_update_node_occ(OloTree* h, const float* p, int occupied, int lazy_eval) {
  OLO_TRY
  return h->tree->updateNode(P(p), occupied != 0, lazy_eval != 0) ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_update_node_logodds(OloTree* h, const float* p, float delta, int lazy_eval) {
  OLO_TRY
  return h->tree->updateNode(P(p), delta, lazy_eval != 0) ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_update_node_key_occ(OloTree* h, const uint16_t* k, int occupied, int lazy_eval) {
  OLO_TRY
  return h->tree->updateNode(K(k), occupied != 0, lazy_eval != 0) ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_update_node_key_logodds(OloTree* h, const uint16_t* k, float delta, int lazy_eval) {
  OLO_TRY
  return h->tree->updateNode(K(k), delta, lazy_eval != 0) ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_set_node_value(OloTree* h, const float* p, float value, int lazy_eval) {
  OLO_TRY
  return h->tree->setNodeValue(P(p), value, lazy_eval != 0) ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_set_node_value_key(OloTree* h, const uint16_t* k, float value, int lazy_eval) {
  OLO_TRY
  return h->tree->setNodeValue(K(k), value, lazy_eval != 0) ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_prune(OloTree* h) {
  OLO_TRY
  h->tree->prune();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_expand(OloTree* h) {
  OLO_TRY
  h->tree->expand();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_to_max_likelihood(OloTree* h) {
  OLO_TRY
  h->tree->toMaxLikelihood();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_clear(OloTree* h) {
  OLO_TRY
  h->tree->clear();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// ---------------------------------------------------------------- I/O

// which: 0 = write (.ot), 1 = writeBinary (non-const, mutates), 2 = writeBinaryConst.
int olo_write(OloTree* h, int which, uint8_t** out, size_t* out_len) {
  OLO_TRY
  *out = nullptr;
  *out_len = 0;
  std::ostringstream os(std::ios_base::out | std::ios_base::binary);
  bool ok;
  switch (which) {
    case 0: ok = h->tree->write(os); break;
    case 1: ok = h->tree->writeBinary(os); break;
    case 2: ok = static_cast<const OcTree*>(h->tree)->writeBinaryConst(os); break;
    default: return OLO_EINVAL;
  }
  if (!ok || !os) return OLO_EFAILED;
  return stream_out(os.str(), out, out_len);
  OLO_CATCH(OLO_EEXCEPTION)
}

// AbstractOcTree::read; NULL unless the result is an octomap::OcTree.
OloTree* olo_read_ot(const uint8_t* data, size_t len) {
  OLO_TRY
  std::istringstream is(std::string(reinterpret_cast<const char*>(data), len),
                        std::ios_base::in | std::ios_base::binary);
  octomap::AbstractOcTree* a = octomap::AbstractOcTree::read(is);
  if (!a) return nullptr;
  OcTree* t = dynamic_cast<OcTree*>(a);
  if (!t) {
    delete a;
    return nullptr;
  }
  return new OloTree(t);
  OLO_CATCH(nullptr)
}

// Fresh OcTree(0.1) + readBinary; NULL on failure.
OloTree* olo_read_bt(const uint8_t* data, size_t len) {
  OLO_TRY
  std::istringstream is(std::string(reinterpret_cast<const char*>(data), len),
                        std::ios_base::in | std::ios_base::binary);
  OloTree* h = new OloTree(new OcTree(0.1));
  if (!h->tree->readBinary(is)) {
    delete h;
    return nullptr;
  }
  return h;
  OLO_CATCH(nullptr)
}

// ---------------------------------------------------------------- queries

// Returns 1 if found (writes logodds, occupied, at_threshold), 0 if not, <0 on error.
int olo_search(const OloTree* h, const float* p, unsigned depth, float* logodds, int* occupied,
               int* at_threshold) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  OLO_TRY
  OcTreeNode* n = h->tree->search(P(p), depth);
  if (!n) return 0;
  *logodds = n->getLogOdds();
  *occupied = h->tree->isNodeOccupied(n) ? 1 : 0;
  *at_threshold = h->tree->isNodeAtThreshold(n) ? 1 : 0;
  return 1;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_search_key(const OloTree* h, const uint16_t* k, unsigned depth, float* logodds, int* occupied,
                   int* at_threshold) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  OLO_TRY
  OcTreeNode* n = h->tree->search(K(k), depth);
  if (!n) return 0;
  *logodds = n->getLogOdds();
  *occupied = h->tree->isNodeOccupied(n) ? 1 : 0;
  *at_threshold = h->tree->isNodeAtThreshold(n) ? 1 : 0;
  return 1;
  OLO_CATCH(OLO_EEXCEPTION)
}

// which: 0 = leaf_iterator (begin_leafs(max_depth)), 1 = tree_iterator (begin_tree(max_depth)).
int olo_dump(const OloTree* h, int which, unsigned max_depth, OloNode** out, size_t* count) {
  *out = nullptr;
  *count = 0;
  if (!valid_depth(max_depth)) return OLO_EINVAL;
  OLO_TRY
  std::vector<OloNode> v;
  const OcTree* t = h->tree;
  if (which == 0) {
    for (OcTree::leaf_iterator it = t->begin_leafs((unsigned char)max_depth), end = t->end_leafs(); it != end;
         ++it) {
      const OcTreeKey& k = it.getKey();
      OloNode n = {{k[0], k[1], k[2]}, (uint8_t)it.getDepth(), 1, it->getLogOdds()};
      v.push_back(n);
    }
  } else if (which == 1) {
    for (OcTree::tree_iterator it = t->begin_tree((unsigned char)max_depth), end = t->end_tree(); it != end;
         ++it) {
      const OcTreeKey& k = it.getKey();
      OloNode n = {{k[0], k[1], k[2]}, (uint8_t)it.getDepth(), (uint8_t)(it.isLeaf() ? 1 : 0), it->getLogOdds()};
      v.push_back(n);
    }
  } else {
    return OLO_EINVAL;
  }
  *out = to_malloc(v);
  *count = v.size();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// Returns 1 if computeRayKeys returned true, 0 if false; keys via *out (3 uint16 per key).
int olo_compute_ray_keys(OloTree* h, const float* origin, const float* end, uint16_t** out, size_t* count) {
  *out = nullptr;
  *count = 0;
  OLO_TRY
  point3d o = P(origin), e = P(end);
  if (!ray_ok(h->tree, o, e)) return OLO_ERAY_TOO_LONG;
  bool ok = h->tree->computeRayKeys(o, e, h->ray);
  std::vector<uint16_t> v;
  v.reserve(3 * h->ray.size());
  for (octomap::KeyRay::const_iterator it = h->ray.begin(); it != h->ray.end(); ++it) {
    v.push_back((*it)[0]);
    v.push_back((*it)[1]);
    v.push_back((*it)[2]);
  }
  *out = to_malloc(v);
  *count = h->ray.size();
  return ok ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

// Returns castRay's bool (1/0). `end` is set to NaN before the call.
int olo_cast_ray(const OloTree* h, const float* origin, const float* direction, int ignore_unknown,
                 double max_range, float* end_out) {
  OLO_TRY
  const float nan = std::numeric_limits<float>::quiet_NaN();
  point3d end(nan, nan, nan);
  bool r = h->tree->castRay(P(origin), P(direction), end, ignore_unknown != 0, max_range);
  put(end_out, end);
  return r ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

// Returns 1 and writes the key if coordToKeyChecked succeeded, 0 otherwise.
int olo_coord_to_key_checked(const OloTree* h, const float* p, unsigned depth, uint16_t* key) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  OcTreeKey k;
  if (!h->tree->coordToKeyChecked(P(p), depth, k)) return 0;
  key[0] = k[0];
  key[1] = k[1];
  key[2] = k[2];
  return 1;
}

int olo_coord_to_key_checked_scalar(const OloTree* h, double c, unsigned depth, uint16_t* key) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  octomap::key_type k;
  if (!h->tree->coordToKeyChecked(c, depth, k)) return 0;
  *key = k;
  return 1;
}

// Unchecked coordToKey(double, depth): wraps around for out-of-range values.
int olo_coord_to_key_scalar(const OloTree* h, double c, unsigned depth, uint16_t* key) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  *key = h->tree->coordToKey(c, depth);
  return OLO_OK;
}

int olo_key_to_coord(const OloTree* h, const uint16_t* k, unsigned depth, float* out) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  put(out, h->tree->keyToCoord(K(k), depth));
  return OLO_OK;
}

int olo_key_to_coord_scalar(const OloTree* h, uint16_t k, unsigned depth, double* out) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  *out = h->tree->keyToCoord(k, depth);
  return OLO_OK;
}

// ---------------------------------------------------------------- statistics

int olo_stats(OloTree* h, OloStats* s) {
  OLO_TRY
  OcTree* t = h->tree;
  const OcTree* ct = t;
  std::memset(s, 0, sizeof(*s));
  s->size = t->size();
  s->num_leaf_nodes = t->getNumLeafNodes();
  s->calc_num_nodes = t->calcNumNodes();
  s->memory_usage = t->memoryUsage();
  s->memory_usage_node = t->memoryUsageNode();
  s->num_changes_detected = t->numChangesDetected();
  s->resolution = t->getResolution();
  s->tree_depth = t->getTreeDepth();
  if (t->getRoot()) {
    s->has_root = 1;
    s->root_logodds = t->getRoot()->getLogOdds();
  }
  // Const overloads first (like the golden harness), then the non-const ones.
  ct->getMetricMin(s->const_metric_min[0], s->const_metric_min[1], s->const_metric_min[2]);
  ct->getMetricMax(s->const_metric_max[0], s->const_metric_max[1], s->const_metric_max[2]);
  ct->getMetricSize(s->const_metric_size[0], s->const_metric_size[1], s->const_metric_size[2]);
  s->memory_full_grid = ct->memoryFullGrid();
  t->getMetricMin(s->metric_min[0], s->metric_min[1], s->metric_min[2]);
  t->getMetricMax(s->metric_max[0], s->metric_max[1], s->metric_max[2]);
  t->getMetricSize(s->metric_size[0], s->metric_size[1], s->metric_size[2]);
  s->volume = t->volume();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

double olo_resolution(const OloTree* h) { return h->tree->getResolution(); }
uint64_t olo_size(const OloTree* h) { return h->tree->size(); }
uint64_t olo_num_leaf_nodes(const OloTree* h) { return h->tree->getNumLeafNodes(); }
uint64_t olo_calc_num_nodes(const OloTree* h) { return h->tree->calcNumNodes(); }
uint64_t olo_memory_usage(const OloTree* h) { return h->tree->memoryUsage(); }
uint64_t olo_memory_full_grid(const OloTree* h) { return h->tree->memoryFullGrid(); }

// Const getMetricMin / getMetricMax overloads.
void olo_metric_min_max_const(const OloTree* h, double* min, double* max) {
  const OcTree* t = h->tree;
  t->getMetricMin(min[0], min[1], min[2]);
  t->getMetricMax(max[0], max[1], max[2]);
}

double olo_volume(OloTree* h) { return h->tree->volume(); }

// Change-detection map contents in the container's (unordered) order.
int olo_changed_keys(const OloTree* h, OloChange** out, size_t* count) {
  *out = nullptr;
  *count = 0;
  OLO_TRY
  std::vector<OloChange> v;
  for (octomap::KeyBoolMap::const_iterator it = h->tree->changedKeysBegin(); it != h->tree->changedKeysEnd(); ++it) {
    OloChange c = {{it->first[0], it->first[1], it->first[2]}, (uint8_t)(it->second ? 1 : 0), 0};
    v.push_back(c);
  }
  *out = to_malloc(v);
  *count = v.size();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// ---------------------------------------------------------------- benchmark batches

// search() for n points; out_logodds[i] = log-odds or NaN if not found. Returns #found (or <0).
long olo_bench_search(const OloTree* h, const float* xyz, size_t n, unsigned depth, float* out_logodds) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  OLO_TRY
  const OcTree* t = h->tree;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  long found = 0;
  for (size_t i = 0; i < n; ++i) {
    OcTreeNode* node = t->search(point3d(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]), depth);
    if (node) {
      ++found;
      out_logodds[i] = node->getLogOdds();
    } else {
      out_logodds[i] = nan;
    }
  }
  return found;
  OLO_CATCH(OLO_EEXCEPTION)
}

// Iterates begin_leafs(max_depth) summing log-odds (in double); returns #leaves (or <0).
long olo_bench_leaf_sum(const OloTree* h, unsigned max_depth, double* sum_out) {
  if (!valid_depth(max_depth)) return OLO_EINVAL;
  OLO_TRY
  const OcTree* t = h->tree;
  double sum = 0.0;
  long n = 0;
  for (OcTree::leaf_iterator it = t->begin_leafs((unsigned char)max_depth), end = t->end_leafs(); it != end; ++it) {
    sum += it->getLogOdds();
    ++n;
  }
  *sum_out = sum;
  return n;
  OLO_CATCH(OLO_EEXCEPTION)
}

// castRay for n rays; ends_out gets 3 floats per ray (NaN if not written), hits_out one byte per ray.
// Returns the number of rays for which castRay returned true (or <0).
long olo_bench_cast_rays(const OloTree* h, const float* origins, const float* directions, size_t n,
                         int ignore_unknown, double max_range, float* ends_out, uint8_t* hits_out) {
  OLO_TRY
  const OcTree* t = h->tree;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  long hits = 0;
  for (size_t i = 0; i < n; ++i) {
    point3d end(nan, nan, nan);
    bool r = t->castRay(P(origins + 3 * i), P(directions + 3 * i), end, ignore_unknown != 0, max_range);
    put(ends_out + 3 * i, end);
    hits_out[i] = r ? 1 : 0;
    if (r) ++hits;
  }
  return hits;
  OLO_CATCH(OLO_EEXCEPTION)
}

size_t olo_sizeof_node(void) { return sizeof(OloNode); }
size_t olo_sizeof_change(void) { return sizeof(OloChange); }
size_t olo_sizeof_stats(void) { return sizeof(OloStats); }
size_t olo_sizeof_sensor(void) { return sizeof(OloSensor); }

// ---------------------------------------------------------------- ColorOcTree

// An octomap::ColorOcTree; colours are uint8_t[3] (r, g, b) per point.
struct OloColorTree {
  octomap::ColorOcTree* tree;
  explicit OloColorTree(octomap::ColorOcTree* t) : tree(t) {}
  ~OloColorTree() { delete tree; }
};

// sensor 1: set the four probabilities in graph2tree order; 2: read the
// defaults back from the fresh tree and set them again (graph2tree's default).
OloColorTree* olo_color_new(double resolution, int sensor, double clamp_min, double clamp_max, double prob_hit,
                            double prob_miss) {
  OLO_TRY
  octomap::ColorOcTree* t = new octomap::ColorOcTree(resolution);
  OloColorTree* h = new OloColorTree(t);
  if (sensor == 2) {
    clamp_min = t->getClampingThresMin();
    clamp_max = t->getClampingThresMax();
    prob_hit = t->getProbHit();
    prob_miss = t->getProbMiss();
  }
  if (sensor) {
    t->setClampingThresMin(clamp_min);
    t->setClampingThresMax(clamp_max);
    t->setProbHit(prob_hit);
    t->setProbMiss(prob_miss);
  }
  return h;
  OLO_CATCH(nullptr)
}

void olo_color_free(OloColorTree* h) { delete h; }

int olo_color_insert_point_cloud(OloColorTree* h, const float* xyz, size_t n, const float* origin, double maxrange,
                                 int lazy_eval, int discretize) {
  OLO_TRY
  octomap::Pointcloud pc;
  fill_cloud(pc, xyz, n);
  point3d o = P(origin);
  if (!cloud_ok(h->tree, pc, o, maxrange, discretize != 0)) return OLO_ERAY_TOO_LONG;
  h->tree->insertPointCloud(pc, o, maxrange, lazy_eval != 0, discretize != 0);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// which: 0 = integrateNodeColor, 1 = averageNodeColor, 2 = setNodeColor, each
// through the (x, y, z, r, g, b) overload, for the n points in order.
// Returns how many calls found a node (non-NULL), or < 0.
long olo_color_apply(OloColorTree* h, int which, const float* xyz, const uint8_t* rgb, size_t n) {
  if (which < 0 || which > 2) return OLO_EINVAL;
  OLO_TRY
  long found = 0;
  for (size_t i = 0; i < n; ++i) {
    float x = xyz[3 * i], y = xyz[3 * i + 1], z = xyz[3 * i + 2];
    uint8_t r = rgb[3 * i], g = rgb[3 * i + 1], b = rgb[3 * i + 2];
    octomap::ColorOcTreeNode* node = nullptr;
    switch (which) {
      case 0: node = h->tree->integrateNodeColor(x, y, z, r, g, b); break;
      case 1: node = h->tree->averageNodeColor(x, y, z, r, g, b); break;
      default: node = h->tree->setNodeColor(x, y, z, r, g, b); break;
    }
    if (node) ++found;
  }
  return found;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_color_update_node(OloColorTree* h, const float* p, int occupied, int lazy_eval) {
  OLO_TRY
  return h->tree->updateNode(P(p), occupied != 0, lazy_eval != 0) ? 1 : 0;
  OLO_CATCH(OLO_EEXCEPTION)
}

// which: 0 = updateInnerOccupancy, 1 = prune, 2 = expand, 3 = toMaxLikelihood.
int olo_color_op(OloColorTree* h, int which) {
  OLO_TRY
  switch (which) {
    case 0: h->tree->updateInnerOccupancy(); break;
    case 1: h->tree->prune(); break;
    case 2: h->tree->expand(); break;
    case 3: h->tree->toMaxLikelihood(); break;
    default: return OLO_EINVAL;
  }
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// write(std::ostream&): the .ot bytes (id ColorOcTree).
int olo_color_write(const OloColorTree* h, uint8_t** out, size_t* out_len) {
  OLO_TRY
  *out = nullptr;
  *out_len = 0;
  std::ostringstream os(std::ios_base::out | std::ios_base::binary);
  if (!h->tree->write(os) || !os) return OLO_EFAILED;
  return stream_out(os.str(), out, out_len);
  OLO_CATCH(OLO_EEXCEPTION)
}

// Returns 1 if found (writes log-odds and colour), 0 if not, < 0 on error.
int olo_color_search(const OloColorTree* h, const float* p, unsigned depth, float* logodds, uint8_t* rgb) {
  if (!valid_depth(depth)) return OLO_EINVAL;
  OLO_TRY
  octomap::ColorOcTreeNode* n = h->tree->search(P(p), depth);
  if (!n) return 0;
  *logodds = n->getLogOdds();
  octomap::ColorOcTreeNode::Color c = n->getColor();
  rgb[0] = c.r;
  rgb[1] = c.g;
  rgb[2] = c.b;
  return 1;
  OLO_CATCH(OLO_EEXCEPTION)
}

// ---------------------------------------------------------------- OcTreeStamped

// An octomap::OcTreeStamped. Its stamps are time(NULL); every mutating call
// reports time(NULL) before and after (t[0], t[1]) so that a caller can tell
// whether a single second was used throughout.
struct OloStampedTree {
  octomap::OcTreeStamped* tree;
  explicit OloStampedTree(octomap::OcTreeStamped* t) : tree(t) {}
  ~OloStampedTree() { delete tree; }
};

struct OloStampedNode {
  uint16_t key[3];
  uint8_t depth;
  uint8_t is_leaf;
  float logodds;
  uint32_t stamp;
};

OloStampedTree* olo_stamped_new(double resolution) {
  OLO_TRY
  return new OloStampedTree(new octomap::OcTreeStamped(resolution));
  OLO_CATCH(nullptr)
}

void olo_stamped_free(OloStampedTree* h) { delete h; }

int olo_stamped_insert_point_cloud(OloStampedTree* h, const float* xyz, size_t n, const float* origin,
                                   double maxrange, int lazy_eval, int discretize, uint32_t* t) {
  OLO_TRY
  octomap::Pointcloud pc;
  fill_cloud(pc, xyz, n);
  point3d o = P(origin);
  if (!cloud_ok(h->tree, pc, o, maxrange, discretize != 0)) return OLO_ERAY_TOO_LONG;
  t[0] = (uint32_t)time(NULL);
  h->tree->insertPointCloud(pc, o, maxrange, lazy_eval != 0, discretize != 0);
  t[1] = (uint32_t)time(NULL);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_stamped_update_node(OloStampedTree* h, const float* p, int occupied, int lazy_eval, uint32_t* t) {
  OLO_TRY
  t[0] = (uint32_t)time(NULL);
  int r = h->tree->updateNode(P(p), occupied != 0, lazy_eval != 0) ? 1 : 0;
  t[1] = (uint32_t)time(NULL);
  return r;
  OLO_CATCH(OLO_EEXCEPTION)
}

// which: 0 = updateInnerOccupancy, 1 = prune, 2 = degradeOutdatedNodes(arg).
int olo_stamped_op(OloStampedTree* h, int which, unsigned arg, uint32_t* t) {
  OLO_TRY
  t[0] = (uint32_t)time(NULL);
  switch (which) {
    case 0: h->tree->updateInnerOccupancy(); break;
    case 1: h->tree->prune(); break;
    case 2: h->tree->degradeOutdatedNodes(arg); break;
    default: return OLO_EINVAL;
  }
  t[1] = (uint32_t)time(NULL);
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

int olo_stamped_write(const OloStampedTree* h, uint8_t** out, size_t* out_len) {
  OLO_TRY
  *out = nullptr;
  *out_len = 0;
  std::ostringstream os(std::ios_base::out | std::ios_base::binary);
  if (!h->tree->write(os) || !os) return OLO_EFAILED;
  return stream_out(os.str(), out, out_len);
  OLO_CATCH(OLO_EEXCEPTION)
}

// Every node (begin_tree), with its stamp.
int olo_stamped_dump(const OloStampedTree* h, OloStampedNode** out, size_t* count) {
  *out = nullptr;
  *count = 0;
  OLO_TRY
  std::vector<OloStampedNode> v;
  const octomap::OcTreeStamped* t = h->tree;
  for (octomap::OcTreeStamped::tree_iterator it = t->begin_tree(), end = t->end_tree(); it != end; ++it) {
    const OcTreeKey& k = it.getKey();
    OloStampedNode n = {{k[0], k[1], k[2]}, (uint8_t)it.getDepth(), (uint8_t)(it.isLeaf() ? 1 : 0),
                        it->getLogOdds(), it->getTimestamp()};
    v.push_back(n);
  }
  *out = to_malloc(v);
  *count = v.size();
  return OLO_OK;
  OLO_CATCH(OLO_EEXCEPTION)
}

// ---------------------------------------------------------------- MapCollection

// MapCollection<MapNode<OcTree>>(path), then isOccupied and getOccupancy for
// the n_pts points, and castRay(origin, direction, end, ignore_unknown,
// max_range) for the n_rays rays (6 floats each: origin, direction; one max
// range each). Returns the number of submaps read, or < 0. castRay's own
// printf chatter goes to stdout.
long olo_mapcoll_query(const char* path, const float* pts, size_t n_pts, uint8_t* occupied, double* occupancy,
                       const float* rays, const double* max_ranges, size_t n_rays, int ignore_unknown,
                       uint8_t* hits, float* ends) {
  OLO_TRY
  octomap::MapCollection<octomap::MapNode<OcTree> > coll(path);
  for (size_t i = 0; i < n_pts; ++i) {
    point3d q = P(pts + 3 * i);
    occupied[i] = coll.isOccupied(q) ? 1 : 0;
    occupancy[i] = coll.getOccupancy(q);
  }
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (size_t i = 0; i < n_rays; ++i) {
    point3d end(nan, nan, nan);
    hits[i] = coll.castRay(P(rays + 6 * i), P(rays + 6 * i + 3), end, ignore_unknown != 0, max_ranges[i]) ? 1 : 0;
    put(ends + 3 * i, end);
  }
  return (long)coll.size();
  OLO_CATCH(OLO_EEXCEPTION)
}

size_t olo_sizeof_stamped_node(void) { return sizeof(OloStampedNode); }

}  // extern "C"
