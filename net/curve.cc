#include "net/curve.h"

#include <sys/stat.h>
#include <zmq.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <sstream>
#include <vector>

#include "common/base/file_io.h"
#include "common/base/log.h"

namespace sandtable::net {

Expected<CurveKeyPair> GenerateCurveKeyPair() {
  std::array<char, 41> public_key{};
  std::array<char, 41> secret_key{};
  if (zmq_curve_keypair(public_key.data(), secret_key.data()) != 0) {
    return UnavailableError("CURVE key generation failed: libzmq built without CURVE support");
  }
  return CurveKeyPair{std::string(public_key.data(), 40), std::string(secret_key.data(), 40)};
}

Status WriteCurveKeyFile(const std::string& path, const CurveKeyPair& keys) {
  const std::string text =
      "# Sandtable site CURVE key pair (Z85). Keep the secret key private (mode 0600).\n"
      "public = " +
      keys.public_key_z85 + "\nsecret = " + keys.secret_key_z85 + "\n";
  Status written = WriteFileAtomically(path, text, kCurveKeyFileMode);
  if (!written.ok()) return written.WithContext("CURVE key file");
  return OkStatus();
}

Status CheckCurveKeyFilePermissions(const std::string& path) {
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT) return NotFoundError(path + ": no such file (CURVE key file)");
    return IoError(path + ": cannot stat CURVE key file (" + std::strerror(errno) + ")");
  }
  if (!S_ISREG(st.st_mode)) return OkStatus();  // ReadInputFile names what it is instead
  if ((st.st_mode & kCurveKeyFileForbiddenBits) != 0) {
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
    return Status(StatusCode::kPermissionDenied,
                  path + ": CURVE key file holds a secret key but its permissions are " + mode +
                      " (group or others may read or write it); refused. Run `chmod 600 " + path +
                      "`");
  }
  return OkStatus();
}

Status CheckCurveKeyPair(const std::string& path, const CurveKeyPair& keys) {
  std::array<char, 41> derived{};
  if (zmq_curve_public(derived.data(), keys.secret_key_z85.c_str()) != 0) {
    return UnavailableError(path +
                            ": cannot derive the public key (libzmq built without CURVE support)");
  }
  if (keys.public_key_z85 != std::string(derived.data(), 40)) {
    return ParseError(path +
                      ": the public key is not the one of the secret key (the 'public' and "
                      "'secret' lines come from different key pairs); regenerate the file with "
                      "`sandtable-coordinator --generate-curve-keys FILE`");
  }
  return OkStatus();
}

Expected<CurveKeyPair> ReadCurveKeyFile(const std::string& path) {
  ST_RETURN_IF_ERROR(CheckCurveKeyFilePermissions(path));
  Expected<std::string> text = ReadInputFile(path, kMaxCurveKeyFileBytes, "kMaxCurveKeyFileBytes");
  if (!text.ok()) return text.status().WithContext("CURVE key file");
  std::istringstream in(*text);
  CurveKeyPair keys;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    std::string name, equals, value, extra;
    fields >> name >> equals >> value >> extra;
    if (name.empty()) continue;  // blank but for spaces
    if (equals != "=" || value.size() != 40 || !extra.empty()) {
      return ParseError(path + ":" + std::to_string(line_number) +
                        ": expected 'public = <40 Z85 chars>' or 'secret = <40 Z85 chars>'");
    }
    if (name == "public") {
      keys.public_key_z85 = value;
    } else if (name == "secret") {
      keys.secret_key_z85 = value;
    } else {
      return ParseError(path + ":" + std::to_string(line_number) + ": unknown key '" + name + "'");
    }
  }
  if (keys.public_key_z85.empty() || keys.secret_key_z85.empty()) {
    return ParseError(path + ": needs both 'public' and 'secret' lines");
  }
  std::array<uint8_t, 32> decoded{};
  if (zmq_z85_decode(decoded.data(), keys.public_key_z85.c_str()) == nullptr) {
    return ParseError(path + ": the 'public' key is not valid Z85");
  }
  if (zmq_z85_decode(decoded.data(), keys.secret_key_z85.c_str()) == nullptr) {
    return ParseError(path + ": the 'secret' key is not valid Z85");
  }
  ST_RETURN_IF_ERROR(CheckCurveKeyPair(path, keys));
  return keys;
}

std::string KeyFingerprint(const std::string& public_key_z85) {
  if (public_key_z85.size() != 40) return "";
  std::array<uint8_t, 32> decoded{};
  if (zmq_z85_decode(decoded.data(), public_key_z85.c_str()) == nullptr) return "";
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  for (int i = 0; i < 8; ++i) {
    if (i > 0 && i % 2 == 0) out += '-';
    out += kHex[decoded[i] >> 4];
    out += kHex[decoded[i] & 15];
  }
  return out;
}

CurveSettings ServerCurve(const CurveKeyPair& site) {
  CurveSettings s;
  s.enabled = true;
  s.server = true;
  s.public_key_z85 = site.public_key_z85;
  s.secret_key_z85 = site.secret_key_z85;
  return s;
}

CurveSettings ClientCurve(const CurveKeyPair& site) {
  CurveSettings s;
  s.enabled = true;
  s.server = false;
  s.public_key_z85 = site.public_key_z85;
  s.secret_key_z85 = site.secret_key_z85;
  s.server_key_z85 = site.public_key_z85;
  return s;
}

ZapHandler::ZapHandler(zmq::context_t* context, std::set<std::string> authorized_public_keys_z85)
    : context_(context), authorized_(std::move(authorized_public_keys_z85)) {}

ZapHandler::~ZapHandler() { Stop(); }

Status ZapHandler::Start() {
  try {
    socket_ = std::make_unique<zmq::socket_t>(*context_, zmq::socket_type::rep);
    socket_->set(zmq::sockopt::linger, 0);
    socket_->bind("inproc://zeromq.zap.01");
  } catch (const zmq::error_t& e) {
    socket_.reset();
    return UnavailableError(std::string("ZAP handler: cannot bind inproc://zeromq.zap.01: ") +
                            e.what());
  }
  thread_ = std::thread([this] { Run(); });
  return OkStatus();
}

void ZapHandler::Stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  socket_.reset();
}

void ZapHandler::Run() {
  // ZAP request (RFC 27): version, request id, domain, address, identity, mechanism,
  // credentials... ; reply: version, request id, status code, status text, user id, metadata.
  while (!stop_) {
    try {
      zmq::pollitem_t item{static_cast<void*>(*socket_), 0, ZMQ_POLLIN, 0};
      zmq::poll(&item, 1, std::chrono::milliseconds(50));
      if (!(item.revents & ZMQ_POLLIN)) continue;
      std::vector<zmq::message_t> request;
      zmq::message_t part;
      do {
        if (!socket_->recv(part, zmq::recv_flags::none)) break;
        request.push_back(std::move(part));
        part = zmq::message_t();
      } while (request.back().more());
      if (request.size() < 6) continue;  // not a ZAP request; REP needs no reply to garbage
      const std::string request_id = request[1].to_string();
      const std::string domain = request[2].to_string();
      const std::string address = request[3].to_string();
      const std::string mechanism = request[5].to_string();
      bool allowed = false;
      std::string client_key = "(none)";
      if (mechanism == "CURVE" && request.size() >= 7 && request[6].size() == 32) {
        std::array<char, 41> z85{};
        zmq_z85_encode(z85.data(), static_cast<const uint8_t*>(request[6].data()), 32);
        client_key.assign(z85.data(), 40);
        allowed = authorized_.count(client_key) > 0 || open_domains_.count(domain) > 0;
      }
      if (allowed) {
        ++accepted_;
      } else {
        ++refused_;
        ST_LOG(kWarning) << "CURVE: refused client " << client_key << " from " << address
                         << " (mechanism " << mechanism << "): key not authorized for this site";
      }
      const std::vector<std::string> reply = {"1.0",
                                              request_id,
                                              allowed ? "200" : "400",
                                              allowed ? "OK" : "key not authorized",
                                              allowed ? client_key : "",
                                              ""};
      for (size_t i = 0; i < reply.size(); ++i) {
        socket_->send(zmq::buffer(reply[i]),
                      i + 1 < reply.size() ? zmq::send_flags::sndmore : zmq::send_flags::none);
      }
    } catch (const zmq::error_t& e) {
      if (e.num() == ETERM) return;
      if (e.num() != EINTR) {
        ST_LOG(kError) << "ZAP handler: " << e.what();
      }
    }
  }
}

}  // namespace sandtable::net
