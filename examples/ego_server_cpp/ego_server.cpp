// Reference AV process in C++ for avrisk's external-ego protocol, version 1
// (docs/ego-protocol.md): a ZeroMQ REP socket (libzmq), msgpack (msgpuck).
// It drives the same adaptive cruise control as the Python reference server
// (avrisk.agents.external.server.AccController, noise 0), with the same
// float64 operations in the same order, so both give the same actions.
//
//   ./ego_server [ADDRESS]      (default tcp://127.0.0.1:5555)
#include <msgpuck.h>
#include <zmq.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

constexpr uint64_t kProtocol = 1;
constexpr int64_t kMaxMessageBytes = 64LL << 20;
const double kPi = 3.14159265358979323846;

// AccController's defaults.
constexpr double kSpeed = 30.0, kHeadway = 1.5, kMinGap = 2.0, kMaxAccel = 1.5,
                 kComfortDecel = 2.0, kCone = 0.2, kLateral = 0.04, kHeading = 0.8;

struct Array {  // a wire array {dtype, shape, data}, checked
  std::string dtype;
  std::vector<uint64_t> shape;
  const char* data = nullptr;
  uint32_t size = 0;
};

struct Fail : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::string str(const char** p) {
  if (mp_typeof(**p) != MP_STR) throw Fail("expected a string");
  uint32_t n;
  const char* s = mp_decode_str(p, &n);
  return std::string(s, n);
}

// The value of `key` in the map at `map`, or nullptr (the message is checked).
const char* find(const char* map, const char* key) {
  if (mp_typeof(*map) != MP_MAP) throw Fail("expected a map");
  uint32_t n = mp_decode_map(&map);
  for (uint32_t i = 0; i < n; ++i) {
    bool is_str = mp_typeof(*map) == MP_STR;
    bool hit = is_str && str(&map) == key;  // str() steps over the key
    if (!is_str) mp_next(&map);
    if (hit) return map;
    mp_next(&map);  // the value
  }
  return nullptr;
}

const char* need(const char* map, const char* key) {
  const char* v = find(map, key);
  if (!v) throw Fail(std::string("missing field ") + key);
  return v;
}

uint64_t uint_of(const char* p) {
  if (mp_typeof(*p) != MP_UINT) throw Fail("expected a non-negative int");
  return mp_decode_uint(&p);
}

Array array_of(const char* map, const char* name) {
  Array a;
  const char* p = need(map, "dtype");
  a.dtype = str(&p);
  p = need(map, "shape");
  if (mp_typeof(*p) != MP_ARRAY) throw Fail(std::string(name) + ": bad shape");
  uint32_t rank = mp_decode_array(&p);
  uint64_t count = 1;
  for (uint32_t i = 0; i < rank; ++i) {
    if (mp_typeof(*p) != MP_UINT) throw Fail(std::string(name) + ": bad shape");
    a.shape.push_back(mp_decode_uint(&p));
    count *= a.shape.back();
  }
  p = need(map, "data");
  if (mp_typeof(*p) != MP_BIN) throw Fail(std::string(name) + ": data not bin");
  a.data = mp_decode_bin(&p, &a.size);
  uint64_t item = a.dtype == "f8" || a.dtype == "i8" ? 8 : a.dtype == "f4" ? 4 : 1;
  if (count * item != a.size) throw Fail(std::string(name) + ": wrong byte count");
  return a;
}

// A float32 field of shape (B) or (B, R), as doubles (little-endian host).
std::vector<double> floats(const char* obs, const char* name, uint64_t b, uint64_t r) {
  Array a = array_of(need(obs, name), name);
  std::vector<uint64_t> want{b};
  if (r) want.push_back(r);
  if (a.dtype != "f4" || a.shape != want) throw Fail(std::string(name) + ": not f4 of the batch");
  std::vector<double> out(a.size / 4);
  for (size_t i = 0; i < out.size(); ++i) {
    float f;
    std::memcpy(&f, a.data + 4 * i, 4);
    out[i] = f;
  }
  return out;
}

class Server {
 public:
  // Writes the reply to `request` into `out`.
  void handle(const char* msg, size_t len, std::vector<char>& out) {
    const char* end = msg + len;
    const char* check = msg;
    try {
      if (len > static_cast<size_t>(kMaxMessageBytes) || mp_check(&check, end) != 0 ||
          check != end)
        throw Fail("not one msgpack message");
      const char* type_p = need(msg, "type");
      std::string type = str(&type_p);
      if (type == "hello") return hello(msg, out);
      if (type == "reset") return reset(msg, out);
      if (type == "step") return step(msg, out);
      throw Fail("unknown message type " + type);
    } catch (const Fail& e) {
      out.resize(64 + std::strlen(e.what()));
      char* w = mp_encode_map(out.data(), 2);
      w = mp_encode_str(w, "type", 4);
      w = mp_encode_str(w, "error", 5);
      w = mp_encode_str(w, "message", 7);
      w = mp_encode_str(w, e.what(), std::strlen(e.what()));
      out.resize(w - out.data());
    }
  }

 private:
  std::vector<double> ahead_;  // 1 for the beams in the forward cone
  uint64_t beams_ = 0, batch_ = 0, episode_ = 0;
  bool reset_ = false;

  void hello(const char* msg, std::vector<char>& out) {
    if (uint_of(need(msg, "protocol")) != kProtocol) throw Fail("protocol 1 only");
    const char* p = need(msg, "lidar_angles");
    if (mp_typeof(*p) != MP_ARRAY) throw Fail("lidar_angles: not an array");
    beams_ = mp_decode_array(&p);
    ahead_.assign(beams_, 0.0);
    for (uint64_t k = 0; k < beams_; ++k) {
      if (mp_typeof(*p) != MP_DOUBLE) throw Fail("lidar_angles: not float64");
      double a = mp_decode_double(&p);
      ahead_[k] = std::fabs(a > kPi ? a - 2 * kPi : a) <= kCone;
    }
    out.resize(128);
    char* w = mp_encode_map(out.data(), 3);
    w = mp_encode_str(w, "type", 4);
    w = mp_encode_str(w, "hello", 5);
    w = mp_encode_str(w, "protocol", 8);
    w = mp_encode_uint(w, kProtocol);
    w = mp_encode_str(w, "server", 6);
    w = mp_encode_str(w, "avrisk-reference-cpp", 20);
    out.resize(w - out.data());
  }

  void reset(const char* msg, std::vector<char>& out) {
    Array seeds = array_of(need(msg, "seeds"), "seeds");
    if (seeds.dtype != "i8" || seeds.shape.size() != 1) throw Fail("seeds: not i8 (B,)");
    batch_ = seeds.shape[0];
    episode_ = uint_of(need(msg, "episode"));
    reset_ = true;
    out.resize(64);
    char* w = mp_encode_map(out.data(), 2);
    w = mp_encode_str(w, "type", 4);
    w = mp_encode_str(w, "reset", 5);
    w = mp_encode_str(w, "episode", 7);
    w = mp_encode_uint(w, episode_);
    out.resize(w - out.data());
  }

  void step(const char* msg, std::vector<char>& out) {
    if (!reset_ || uint_of(need(msg, "episode")) != episode_) throw Fail("step before reset");
    uint64_t t = uint_of(need(msg, "step"));
    const char* obs = need(msg, "obs");
    const uint64_t b = batch_, r = beams_;
    std::vector<double> v = floats(obs, "speed", b, 0), len = floats(obs, "length", b, 0),
                        lat = floats(obs, "lateral_offset", b, 0),
                        head = floats(obs, "heading_offset", b, 0), range, rate;
    if (r) {
      range = floats(obs, "lidar_range", b, r);
      rate = floats(obs, "lidar_range_rate", b, r);
    }
    std::vector<double> accel(b), steer(b);
    const double brake = 2.0 * std::sqrt(kMaxAccel * kComfortDecel);
    for (uint64_t i = 0; i < b; ++i) {
      double gap = INFINITY, closing = 0.0;
      bool found = false;
      for (uint64_t k = 0; k < r; ++k) {  // the first shortest forward beam
        double rk = range[i * r + k];
        if (ahead_[k] != 0.0 && (!found || rk < gap)) {
          gap = rk;
          closing = -rate[i * r + k];
          found = true;
        }
      }
      if (found) gap = gap - 0.5 * len[i];
      double ratio = v[i] / kSpeed, ratio2 = ratio * ratio;
      double wanted = kMinGap + std::fmax(0.0, v[i] * kHeadway + v[i] * closing / brake);
      double inter = wanted / std::fmax(gap, 0.1);
      accel[i] = kMaxAccel * (1.0 - ratio2 * ratio2 - inter * inter);
      steer[i] = -(kLateral * lat[i] + kHeading * head[i]);
    }
    out.resize(256 + 2 * (b * 8 + 64));
    char* w = mp_encode_map(out.data(), 5);
    w = mp_encode_str(w, "type", 4);
    w = mp_encode_str(w, "step", 4);
    w = mp_encode_str(w, "episode", 7);
    w = mp_encode_uint(w, episode_);
    w = mp_encode_str(w, "step", 4);
    w = mp_encode_uint(w, t);
    for (auto* field : {&accel, &steer}) {
      w = mp_encode_str(w, field == &accel ? "accel" : "steer", 5);
      w = mp_encode_map(w, 3);
      w = mp_encode_str(w, "dtype", 5);
      w = mp_encode_str(w, "f8", 2);
      w = mp_encode_str(w, "shape", 5);
      w = mp_encode_array(w, 1);
      w = mp_encode_uint(w, b);
      w = mp_encode_str(w, "data", 4);
      w = mp_encode_bin(w, reinterpret_cast<const char*>(field->data()), b * 8);
    }
    out.resize(w - out.data());
  }
};

}  // namespace

int main(int argc, char** argv) {
  const char* address = argc > 1 ? argv[1] : "tcp://127.0.0.1:5555";
  void* context = zmq_ctx_new();
  void* socket = zmq_socket(context, ZMQ_REP);
  int64_t max_bytes = kMaxMessageBytes;
  zmq_setsockopt(socket, ZMQ_MAXMSGSIZE, &max_bytes, sizeof max_bytes);
  if (zmq_bind(socket, address) != 0) {
    std::fprintf(stderr, "cannot bind %s: %s\n", address, zmq_strerror(zmq_errno()));
    return 1;
  }
  std::printf("serving the ego at %s\n", address);
  std::fflush(stdout);
  Server server;
  std::vector<char> reply;
  for (;;) {
    zmq_msg_t request;
    zmq_msg_init(&request);
    if (zmq_msg_recv(&request, socket, 0) < 0) break;
    server.handle(static_cast<const char*>(zmq_msg_data(&request)), zmq_msg_size(&request),
                  reply);
    zmq_msg_close(&request);
    if (zmq_send(socket, reply.data(), reply.size(), 0) < 0) break;
  }
  zmq_close(socket);
  zmq_ctx_term(context);
  return 0;
}
