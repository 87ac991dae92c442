// CURVE security: site key files and a ZAP handler that refuses unknown clients.
//
// Site scheme (docs/protocol.md): every process of a site is given the same site key file
// (`sandtable-coordinator --generate-curve-keys site.key`). Servers (bound ROUTER sockets)
// use it as their CURVE key pair; clients (DEALERs) use it as their own key pair and as the
// server's public key. A ZAP handler accepts a client only if its public key is in the
// authorized set (the site key, plus any extra keys). Clients without CURVE, or with another
// key pair, get no connection; the refusal is logged and counted.
//
// Key file format (text, '#' comments):
//   public = <40 Z85 characters>
//   secret = <40 Z85 characters>
//
// Key file rules (docs/reliability.md): the file holds a secret, so it is written with
// mode 0600 (owner read/write) through WriteFileAtomically, and a key file that group or others
// may read or write (any of the bits 0077) is refused on load, as ssh refuses an unprotected
// private key. The two halves must belong together: the public key derived from the secret
// (zmq_curve_public) must equal the file's public key, else the file is refused naming it (a
// mismatched pair would otherwise only show up as a client that never gets through).
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <set>
#include <string>
#include <thread>

#include <zmq.hpp>

#include "common/base/status.h"
#include "net/socket.h"

namespace sandtable::net {

struct CurveKeyPair {
  std::string public_key_z85;
  std::string secret_key_z85;
};

// Mode of a written key file, and the permission bits that make a key file refused on load.
inline constexpr unsigned kCurveKeyFileMode = 0600;
inline constexpr unsigned kCurveKeyFileForbiddenBits = 0077;
// A key file is two lines and a comment; anything longer is not one.
inline constexpr uint64_t kMaxCurveKeyFileBytes = 64 * 1024;

Expected<CurveKeyPair> GenerateCurveKeyPair();
// Writes atomically with mode kCurveKeyFileMode; IO_ERROR naming the path (old file kept).
Status WriteCurveKeyFile(const std::string& path, const CurveKeyPair& keys);
// Refuses, naming the file: NOT_FOUND (missing), PERMISSION_DENIED (readable or writable by
// group/others), IO_ERROR (not a regular file, over kMaxCurveKeyFileBytes), PARSE_ERROR (bad
// line, bad Z85, public key not derived from the secret key).
Expected<CurveKeyPair> ReadCurveKeyFile(const std::string& path);
// The parts of ReadCurveKeyFile, for callers that hold keys from elsewhere.
Status CheckCurveKeyFilePermissions(const std::string& path);
Status CheckCurveKeyPair(const std::string& path, const CurveKeyPair& keys);

// How an operator reads a CURVE public key (docs/deploy.md, "Accepting a new unit"): the first
// 8 of its 32 bytes in hex, in four groups ("3f9a-01c2-77de-b450"). Empty for a key that is not
// 40 characters of Z85.
std::string KeyFingerprint(const std::string& public_key_z85);

// The ZAP domain of the coordinator's enrollment socket, where any CURVE key is let through
// (ZapHandler::AdmitAnyKeyIn) so a unit without the site's key can ask to be accepted.
inline constexpr char kEnrollZapDomain[] = "sandtable-enroll";

// Socket settings for a bound (server) or connecting (client) socket of a site.
CurveSettings ServerCurve(const CurveKeyPair& site);
CurveSettings ClientCurve(const CurveKeyPair& site);

// Answers ZAP requests (RFC 27) for one context on inproc://zeromq.zap.01 in its own thread.
// Start it before binding any CURVE server socket of that context; Stop() (or the destructor)
// before the context is closed. Every client let through gets its public key (Z85) as its
// ZAP User-Id, which each message it sends carries (Incoming::peer_key).
class ZapHandler {
 public:
  ZapHandler(zmq::context_t* context, std::set<std::string> authorized_public_keys_z85);
  ~ZapHandler();
  // In `domain` (a socket's CurveSettings::zap_domain) any CURVE client is let through, and
  // only there: the enrollment socket's handler decides what a stranger may ask. Call before
  // Start().
  void AdmitAnyKeyIn(const std::string& domain) { open_domains_.insert(domain); }
  Status Start();
  void Stop();

  uint64_t accepted() const { return accepted_.load(); }
  uint64_t refused() const { return refused_.load(); }

 private:
  void Run();
  zmq::context_t* context_;
  std::set<std::string> authorized_;
  std::set<std::string> open_domains_;
  std::unique_ptr<zmq::socket_t> socket_;
  std::thread thread_;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> accepted_{0};
  std::atomic<uint64_t> refused_{0};
};

}  // namespace sandtable::net
