#include "coordinator/membership/enrollment_command.h"

#include <chrono>
#include <cstdio>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>

#include "common/base/ids.h"
#include "common/cli/command_line.h"
#include "net/channel.h"
#include "net/curve.h"
#include "net/server_loop.h"
#include "net/socket.h"

namespace sandtable::coordinator {
namespace {

using Clock = std::chrono::steady_clock;

// One request, its reply (or UNAVAILABLE when none came within `timeout`).
Expected<wire::EnrollmentReply> Ask(const std::string& endpoint, const net::CurveKeyPair& site,
                                    const wire::EnrollmentRequest& request,
                                    std::chrono::milliseconds timeout) {
  zmq::context_t context;
  net::SocketOptions options;
  options.curve = net::ClientCurve(site);
  Expected<std::unique_ptr<net::Socket>> dealer =
      net::Socket::Create(&context, net::SocketType::kDealer, options);
  if (!dealer.ok()) return dealer.status();
  ST_RETURN_IF_ERROR((*dealer)->Connect(endpoint));
  proto::MessageCounters counters;
  net::Channel channel(std::move(*dealer), kOperatorSenderId, net::NewIncarnation(), &counters);
  wire::Envelope ask;
  *ask.mutable_enrollment_request() = request;
  ST_RETURN_IF_ERROR(channel.Send(std::move(ask)));
  const Clock::time_point deadline = Clock::now() + timeout;
  while (Clock::now() < deadline) {
    std::vector<bool> readable;
    ST_RETURN_IF_ERROR(
        net::Socket::Poll({&channel.socket()}, std::chrono::milliseconds(50), &readable));
    if (!readable[0]) continue;
    Expected<std::optional<net::Incoming>> in = channel.TryReceive();
    if (!in.ok() || !in->has_value()) continue;
    const wire::Envelope& reply = (*in)->envelope;
    if (reply.has_enrollment_reply()) return reply.enrollment_reply();
    if (reply.has_rejected()) {
      return UnavailableError("the coordinator at " + endpoint +
                              " does not serve enrollment requests: " + reply.rejected().reason());
    }
  }
  return UnavailableError("no answer from " + endpoint + " in " + std::to_string(timeout.count()) +
                          " ms: is the coordinator running there, and is this the site's key "
                          "file? (a CURVE handshake with another key is never answered)");
}

void PrintTable(const wire::EnrollmentReply& reply, const std::string& site_key) {
  std::cout << "site key " << net::KeyFingerprint(site_key) << "\n";
  if (reply.units().empty()) {
    std::cout << "no unit is asking to join\n";
    return;
  }
  std::printf("%-19s  %-8s  %-20s  %-15s  %6s  %8s  %8s\n", "FINGERPRINT", "STATE", "HOST",
              "ADDRESS", "NODE", "WAITING", "REQUESTS");
  for (const wire::EnrollingUnit& u : reply.units()) {
    std::printf("%-19s  %-8s  %-20s  %-15s  %6u  %6.0f s  %8llu\n", u.fingerprint().c_str(),
                u.state().c_str(), u.host_name().c_str(), u.address().c_str(), u.node_id(),
                u.waiting_s(), static_cast<unsigned long long>(u.requests()));
  }
}

void PrintJson(const wire::EnrollmentReply& reply, const std::string& site_key) {
  nlohmann::json out;
  out["site_key"] = net::KeyFingerprint(site_key);
  out["ok"] = reply.ok();
  out["message"] = reply.message();
  out["units"] = nlohmann::json::array();
  for (const wire::EnrollingUnit& u : reply.units()) {
    out["units"].push_back({{"fingerprint", u.fingerprint()},
                            {"public_key", u.public_key()},
                            {"state", u.state()},
                            {"host", u.host_name()},
                            {"address", u.address()},
                            {"node", u.node_id()},
                            {"waiting_s", u.waiting_s()},
                            {"requests", u.requests()}});
  }
  std::cout << out.dump() << "\n";
}

}  // namespace

int RunEnrollmentCommand(const std::vector<std::string>& args) {
  std::string endpoint, keys_path, accept, refuse;
  int timeout_ms = 3000;
  bool json = false;
  CLI::App app(
      "The units that ask to join the site (a node started with --enroll), and the operator's "
      "decision on one (docs/deploy.md, \"Accepting a new unit\").",
      "sandtable-coordinator enrollment");
  cli::Configure(app);
  app.add_option("--requests", endpoint,
                 "the serving coordinator's requests endpoint, e.g. tcp://127.0.0.1:7000")
      ->required()
      ->check(cli::Endpoint());
  app.add_option("--curve-keys", keys_path, "the site's CURVE key file")->required();
  CLI::Option* accept_option = app.add_option(
      "--accept", accept, "accept the unit with this fingerprint (as it logs it) or public key");
  app.add_option("--refuse", refuse, "refuse the unit with this fingerprint or public key")
      ->excludes(accept_option);
  app.add_option("--timeout-ms", timeout_ms, "how long to wait for the coordinator's answer")
      ->check(cli::Integer(100, 600000));
  app.add_flag("--json", json, "print the answer as one JSON line");
  if (std::optional<int> exit = cli::Parse(app, args)) return *exit;

  Expected<net::CurveKeyPair> site = net::ReadCurveKeyFile(keys_path);
  if (!site.ok()) return cli::UsageError(app, "--curve-keys: " + site.status().message());
  wire::EnrollmentRequest request;
  request.set_accept(accept);
  request.set_refuse(refuse);
  Expected<wire::EnrollmentReply> reply =
      Ask(endpoint, *site, request, std::chrono::milliseconds(timeout_ms));
  if (!reply.ok()) {
    std::cerr << "sandtable-coordinator enrollment: " << reply.status().message() << "\n";
    return cli::kExitFailure;
  }
  if (json) {
    PrintJson(*reply, site->public_key_z85);
  } else {
    if (!reply->message().empty()) {
      (reply->ok() ? std::cout : std::cerr) << reply->message() << "\n";
    }
    PrintTable(*reply, site->public_key_z85);
  }
  return reply->ok() ? cli::kExitOk : cli::kExitFailure;
}

}  // namespace sandtable::coordinator
