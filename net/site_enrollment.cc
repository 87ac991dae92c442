#include "net/site_enrollment.h"

#include <unistd.h>

#include <filesystem>
#include <system_error>

#include "net/channel.h"
#include "net/server_loop.h"
#include "net/socket.h"

namespace sandtable::net {
namespace {

using Clock = std::chrono::steady_clock;

// The unit's own key pair: the one kept beside the key file while it waits, or a new one.
Expected<CurveKeyPair> RequestKeys(const std::string& key_file, const EnrollmentLog& log) {
  const std::string path = key_file + ".request";
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) {
    Expected<CurveKeyPair> kept = ReadCurveKeyFile(path);
    if (kept.ok()) return kept;
    log("enrollment: " + kept.status().message() + "; making a new key for this unit");
  }
  Expected<CurveKeyPair> keys = GenerateCurveKeyPair();
  if (!keys.ok()) return keys.status();
  ST_RETURN_IF_ERROR(WriteCurveKeyFile(path, *keys).WithContext("enrollment: the unit's key"));
  return keys;
}

std::string Seconds(Clock::duration d) {
  return std::to_string(std::chrono::duration_cast<std::chrono::seconds>(d).count()) + " s";
}

}  // namespace

std::string ThisHostName() {
  char name[256] = {};
  if (::gethostname(name, sizeof(name) - 1) != 0) return "unknown";
  return name;
}

Status EnrollmentClientOptions::Check() const {
  if (endpoint.empty()) return InvalidArgumentError("enrollment: no endpoint to ask");
  if (KeyFingerprint(site_public_key).empty()) {
    return InvalidArgumentError("enrollment: the site's key is not a CURVE public key");
  }
  if (key_file.empty()) return InvalidArgumentError("enrollment: no key file to write");
  if (ask_period.count() < 10 || ask_period.count() > 60000) {
    return InvalidArgumentError("enrollment: ask_period must be in [10, 60000] ms");
  }
  if (timeout.count() < 0) return InvalidArgumentError("enrollment: timeout must be >= 0");
  return OkStatus();
}

Expected<CurveKeyPair> EnrollWithSite(const EnrollmentClientOptions& options,
                                      const std::atomic<bool>* stop,
                                      const EnrollmentLog& given_log) {
  ST_RETURN_IF_ERROR(options.Check());
  const EnrollmentLog log = given_log ? given_log : [](const std::string&) {};
  Expected<CurveKeyPair> own = RequestKeys(options.key_file, log);
  if (!own.ok()) return own.status();
  const std::string fingerprint = KeyFingerprint(own->public_key_z85);

  zmq::context_t context;
  SocketOptions socket_options;
  socket_options.curve.enabled = true;
  socket_options.curve.public_key_z85 = own->public_key_z85;
  socket_options.curve.secret_key_z85 = own->secret_key_z85;
  socket_options.curve.server_key_z85 = options.site_public_key;
  socket_options.reconnect_interval_max = std::chrono::milliseconds(2000);
  Expected<std::unique_ptr<Socket>> dealer =
      Socket::Create(&context, SocketType::kDealer, socket_options);
  if (!dealer.ok()) return dealer.status();
  ST_RETURN_IF_ERROR((*dealer)->Connect(options.endpoint));
  proto::MessageCounters counters;
  Channel channel(std::move(*dealer), options.node_id, NewIncarnation(), &counters);

  const std::string host_name = options.host_name.empty() ? ThisHostName() : options.host_name;
  log("enrollment: asking the site at " + options.endpoint + " (coordinator key " +
      KeyFingerprint(options.site_public_key) + ") to accept this unit, fingerprint " +
      fingerprint);
  const Clock::time_point start = Clock::now();
  Clock::time_point next_ask = start, last_reply = start,
                    next_silence_note = start + std::chrono::seconds(5);
  Clock::time_point next_pending_note = start;
  std::string last_heard = "nothing";
  while (stop == nullptr || !stop->load()) {
    const Clock::time_point now = Clock::now();
    if (options.timeout.count() > 0 && now - start >= options.timeout) break;
    if (now >= next_ask) {
      wire::Envelope ask;
      ask.mutable_enroll_request()->set_host_name(host_name);
      if (Status sent = channel.Send(std::move(ask)); !sent.ok()) {
        last_heard = "send failed: " + sent.message();
      }
      next_ask = now + options.ask_period;
    }
    if (now >= next_silence_note && now - last_reply >= std::chrono::seconds(5)) {
      log("enrollment: no answer from " + options.endpoint + " for " + Seconds(now - last_reply) +
          " (is the coordinator running with --enroll, and its enrollment port open in the "
          "firewall?); still asking");
      next_silence_note =
          now + std::min<Clock::duration>(2 * (now - start), std::chrono::minutes(1));
    }
    std::vector<bool> readable;
    ST_RETURN_IF_ERROR(Socket::Poll({&channel.socket()}, std::chrono::milliseconds(50), &readable));
    if (!readable[0]) continue;
    Expected<std::optional<Incoming>> in = channel.TryReceive();
    if (!in.ok()) {
      last_heard = "a message refused: " + in.status().message();
      continue;
    }
    if (!in->has_value()) continue;
    const wire::Envelope& envelope = (*in)->envelope;
    last_reply = Clock::now();
    if (envelope.has_rejected()) {
      last_heard = "rejected: " + envelope.rejected().reason();
      continue;
    }
    if (!envelope.has_enroll_reply()) {
      last_heard = "an unexpected " + proto::BodyName(envelope);
      continue;
    }
    const wire::EnrollReply& reply = envelope.enroll_reply();
    switch (reply.state()) {
      case wire::EnrollReply::STATE_ACCEPTED: {
        CurveKeyPair site{reply.site_public_key(), reply.site_secret_key()};
        if (site.public_key_z85 != options.site_public_key) {
          return Status(
              StatusCode::kPermissionDenied,
              "enrollment: the key handed over is not the key of the site that was asked");
        }
        ST_RETURN_IF_ERROR(CheckCurveKeyPair("the site's key handed over", site));
        ST_RETURN_IF_ERROR(WriteCurveKeyFile(options.key_file, site));
        std::error_code ec;
        std::filesystem::remove(options.key_file + ".request", ec);
        log("enrollment: accepted by the site's operator after " + Seconds(Clock::now() - start) +
            "; the site's key is in " + options.key_file);
        return site;
      }
      case wire::EnrollReply::STATE_REFUSED:
        return Status(StatusCode::kPermissionDenied, "enrollment: the site at " + options.endpoint +
                                                         " refused this unit (fingerprint " +
                                                         fingerprint + "): " + reply.message());
      default:
        last_heard = "pending";
        if (Clock::now() >= next_pending_note) {
          log("enrollment: waiting " + Seconds(Clock::now() - start) +
              " for the site's operator to accept this unit; on the coordinator: "
              "sandtable-coordinator enrollment --accept " +
              fingerprint);
          next_pending_note = Clock::now() + std::chrono::seconds(30);
        }
        break;
    }
  }
  return UnavailableError("enrollment: asked " + options.endpoint + " for " +
                          Seconds(Clock::now() - start) +
                          " with no decision (last heard: " + last_heard + ")");
}

}  // namespace sandtable::net
