#include "sim/lab/lab_painter.h"

#include <algorithm>
#include <cstring>
#include <memory>
#include <set>
#include <string>
#include <utility>

#include <zmq.hpp>

#include "common/base/ids.h"
#include "net/channel.h"
#include "net/socket.h"
#include "proto/message_counters.h"

namespace sandtable::sim {

using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

nlohmann::json LabPainterResult::ToJson() const {
  nlohmann::json outages_json = nlohmann::json::array();
  for (const LabPainterOutage& o : outages) {
    outages_json.push_back({{"from_s", o.from_s}, {"to_s", o.to_s}});
  }
  nlohmann::json j = {{"strokes", strokes},
                      {"requests_sent", requests_sent},
                      {"points_acknowledged", points_acknowledged},
                      {"refused", refused},
                      {"outages", outages_json},
                      {"verified", verified},
                      {"points_present", points_present},
                      {"points_lost", points_lost}};
  if (!first_refusal.empty()) j["first_refusal"] = first_refusal;
  if (!verify_error.empty()) j["verify_error"] = verify_error;
  return j;
}

Eigen::Vector3f LabPainterPoint(uint64_t stroke_id, uint32_t k) {
  return Eigen::Vector3f(-0.25f + 0.004f * static_cast<float>(k % 125),
                         -0.2f + 0.01f * static_cast<float>(stroke_id % 40), 0.0f);
}

namespace {

// One connection to the coordinator: its own incarnation, its own request numbering, and a
// monitor of its connection (a coordinator that dies drops it at once: what was in flight is
// lost, no need to wait out the ack timeout).
struct Link {
  std::unique_ptr<net::Channel> channel;
  std::unique_ptr<zmq::socket_t> monitor;  // PAIR of zmq_socket_monitor (null: none)
  uint64_t sent = 0;
  // Whether the connection dropped since the last call (drains the monitor).
  bool Dropped() {
    bool dropped = false;
    while (monitor) {
      zmq::message_t event, address;
      try {
        if (!monitor->recv(event, zmq::recv_flags::dontwait)) break;
        if (event.more()) (void)monitor->recv(address, zmq::recv_flags::dontwait);
      } catch (const zmq::error_t&) {
        break;
      }
      uint16_t code = 0;
      if (event.size() >= sizeof(code)) std::memcpy(&code, event.data(), sizeof(code));
      dropped = dropped || code == ZMQ_EVENT_DISCONNECTED;
    }
    return dropped;
  }
};

Expected<Link> Connect(zmq::context_t* context, const LabPainterOptions& options,
                       uint64_t incarnation, proto::MessageCounters* counters) {
  net::SocketOptions socket_options;
  if (options.site_keys) socket_options.curve = net::ClientCurve(*options.site_keys);
  socket_options.linger = milliseconds(0);
  Expected<std::unique_ptr<net::Socket>> socket =
      net::Socket::Create(context, net::SocketType::kDealer, socket_options);
  if (!socket.ok()) return socket.status();
  ST_RETURN_IF_ERROR((*socket)->Connect(options.requests_endpoint));
  Link link;
  const std::string monitor_endpoint =
      "inproc://lab-painter-monitor-" + std::to_string(incarnation);
  if (zmq_socket_monitor((*socket)->raw().handle(), monitor_endpoint.c_str(),
                         ZMQ_EVENT_DISCONNECTED) == 0) {
    try {
      link.monitor = std::make_unique<zmq::socket_t>(*context, zmq::socket_type::pair);
      link.monitor->set(zmq::sockopt::linger, 0);
      link.monitor->connect(monitor_endpoint);
    } catch (const zmq::error_t&) {
      link.monitor.reset();  // the ack timeout alone then
    }
  }
  link.channel = std::make_unique<net::Channel>(std::move(*socket), kLabPainterSenderId,
                                                incarnation, counters);
  return link;
}

}  // namespace

Status LabPainterOptions::Check() const {
  if (requests_endpoint.empty()) {
    return InvalidArgumentError("lab painter: the coordinator's requests endpoint is needed");
  }
  if (!(points_per_s > 0.0) || window < 1 || ack_timeout.count() <= 0) {
    return InvalidArgumentError(
        "lab painter: points_per_s and ack_timeout must be > 0, window at least 1");
  }
  return OkStatus();
}

LabPainter::LabPainter(LabPainterOptions options) : options_(std::move(options)) {}

LabPainter::~LabPainter() { Stop(); }

void LabPainter::Start() {
  started_ = Clock::now();
  stop_ = false;
  thread_ = std::thread([this] { Run(); });
}

void LabPainter::Stop() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
}

double LabPainter::last_ack_s() const {
  const int64_t ns = last_ack_ns_.load();
  return ns < 0 ? -1.0 : ns * 1e-9;
}

double LabPainter::FirstAckAfter(double s) const {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = std::lower_bound(ack_times_s_.begin(), ack_times_s_.end(), s);
  return it == ack_times_s_.end() ? -1.0 : *it;
}

LabPainterResult LabPainter::result() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return result_;
}

void LabPainter::Run() {
  zmq::context_t context;
  proto::MessageCounters counters;
  uint64_t incarnation = static_cast<uint64_t>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
          .count());
  Expected<Link> link = Connect(&context, options_, ++incarnation, &counters);
  if (!link.ok()) {
    std::lock_guard<std::mutex> lock(mutex_);
    result_.verify_error = "painter: " + link.status().ToString();
    return;
  }
  const auto seconds = [&](Clock::time_point t) {
    return std::chrono::duration<double>(t - started_).count();
  };
  // request sequence -> (stroke, point index or -1 for the stroke's begin)
  std::map<uint64_t, std::pair<uint64_t, int64_t>> in_flight;
  uint64_t stroke = options_.first_stroke_id;
  bool begun = false;
  uint32_t next_point = 0;
  Clock::time_point last_progress = Clock::now(), next_send = Clock::now();
  Clock::time_point last_ack{};
  bool in_outage = false;
  const auto period = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(1.0 / std::max(options_.points_per_s, 1e-3)));
  auto send = [&](wire::AnnotationEvent event, int64_t point) {
    wire::Envelope e;
    *e.mutable_annotation_request() = std::move(event);
    if (!link->channel->Send(std::move(e)).ok()) return;  // queue full: try later
    in_flight[++link->sent] = {stroke, point};
    std::lock_guard<std::mutex> lock(mutex_);
    ++result_.requests_sent;
  };
  while (!stop_) {
    const Clock::time_point now = Clock::now();
    if (!begun && in_flight.empty()) {
      wire::AnnotationEvent begin;
      auto* b = begin.mutable_stroke_begin();
      b->set_stroke_id(stroke);
      b->set_color_r(1.0f);
      b->set_color_g(0.4f);
      b->set_color_b(0.0f);
      b->set_width_m(0.006f);
      send(std::move(begin), -1);
      next_point = 0;
    } else if (begun && static_cast<int>(in_flight.size()) < options_.window && now >= next_send) {
      wire::AnnotationEvent points;
      auto* p = points.mutable_stroke_points();
      p->set_stroke_id(stroke);
      p->set_first_point_index(next_point);
      const Eigen::Vector3f x = LabPainterPoint(stroke, next_point);
      p->add_points_in_table_m(x.x());
      p->add_points_in_table_m(x.y());
      p->add_points_in_table_m(x.z());
      send(std::move(points), next_point);
      ++next_point;
      next_send = std::max(next_send + period, now - period);
    }
    std::vector<bool> readable;
    (void)net::Socket::Poll({&link->channel->socket()}, milliseconds(5), &readable);
    while (true) {
      Expected<std::optional<net::Incoming>> in = link->channel->TryReceive();
      if (!in.ok()) continue;  // a refused message: counted, carry on
      if (!*in) break;
      const wire::Envelope& reply = (*in)->envelope;
      if (!reply.has_annotation_ack()) continue;
      const wire::AnnotationAck& ack = reply.annotation_ack();
      auto it = in_flight.find(ack.request_sequence());
      if (it == in_flight.end()) continue;
      const auto [acked_stroke, point] = it->second;
      in_flight.erase(it);
      const Clock::time_point t = Clock::now();
      last_progress = t;
      std::lock_guard<std::mutex> lock(mutex_);
      if (!ack.accepted()) {
        ++result_.refused;
        if (result_.first_refusal.empty()) result_.first_refusal = ack.reason();
        if (acked_stroke == stroke) {  // start over on a fresh stroke
          begun = false;
          ++stroke;
        }
        continue;
      }
      last_ack = t;
      ack_times_s_.push_back(seconds(t));
      last_ack_ns_ = std::chrono::duration_cast<std::chrono::nanoseconds>(t - started_).count();
      if (in_outage) {
        result_.outages.back().to_s = seconds(t);
        in_outage = false;
      }
      if (point < 0) {
        begun = begun || acked_stroke == stroke;
        ++result_.strokes;
      } else {
        acked_[acked_stroke].push_back(static_cast<uint32_t>(point));
        ++result_.points_acknowledged;
      }
    }
    const bool dropped = link->Dropped();
    if ((!in_flight.empty() || dropped) &&
        (dropped || Clock::now() - last_progress > options_.ack_timeout)) {
      // The connection dropped (the coordinator died) or no answer came (the requests were
      // lost): what is in flight is lost. Reconnect, new stroke.
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (!in_outage) {
          result_.outages.push_back(
              {last_ack == Clock::time_point{} ? 0.0 : seconds(last_ack), -1.0});
          in_outage = true;
        }
      }
      in_flight.clear();
      begun = false;
      ++stroke;
      Expected<Link> fresh = Connect(&context, options_, ++incarnation, &counters);
      if (fresh.ok()) link = std::move(fresh);
      last_progress = Clock::now();
    }
  }
}

LabPainterResult LabPainter::Verify(milliseconds timeout) {
  Stop();
  LabPainterResult out = result();
  std::map<uint64_t, std::vector<uint32_t>> acked;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    acked = acked_;
  }
  zmq::context_t context;
  proto::MessageCounters counters;
  Expected<Link> link = Connect(&context, options_, 1, &counters);
  if (!link.ok()) {
    out.verify_error = link.status().ToString();
    return out;
  }
  wire::Envelope request;
  request.mutable_catch_up_request()->set_last_seen_sequence(0);
  if (Status sent = link->channel->Send(std::move(request)); !sent.ok()) {
    out.verify_error = sent.ToString();
    return out;
  }
  const Clock::time_point until = Clock::now() + timeout;
  std::optional<wire::CatchUpReply> reply;
  while (!reply && Clock::now() < until) {
    std::vector<bool> readable;
    (void)net::Socket::Poll({&link->channel->socket()}, milliseconds(20), &readable);
    Expected<std::optional<net::Incoming>> in = link->channel->TryReceive();
    if (in.ok() && *in && (*in)->envelope.has_catch_up_reply()) {
      reply = (*in)->envelope.catch_up_reply();
    }
  }
  if (!reply) {
    out.verify_error = "no catch-up reply from " + options_.requests_endpoint + " within " +
                       std::to_string(timeout.count()) + " ms";
    return out;
  }
  if (!reply->snapshot_sent() || !reply->snapshot_chunk().empty()) {
    out.verify_error = "the catch-up from 0 did not come as one snapshot";
    return out;
  }
  std::map<uint64_t, const wire::Snapshot::Stroke*> strokes;
  for (const wire::Snapshot::Stroke& s : reply->snapshot().strokes()) {
    strokes[s.begin().stroke_id()] = &s;
  }
  for (const auto& [id, points] : acked) {
    auto it = strokes.find(id);
    for (uint32_t k : points) {
      bool present = false;
      if (it != strokes.end() &&
          static_cast<int>(3 * k + 2) < it->second->points_in_table_m_size()) {
        const Eigen::Vector3f x = LabPainterPoint(id, k);
        present = it->second->points_in_table_m(3 * k) == x.x() &&
                  it->second->points_in_table_m(3 * k + 1) == x.y() &&
                  it->second->points_in_table_m(3 * k + 2) == x.z();
      }
      ++(present ? out.points_present : out.points_lost);
    }
  }
  out.verified = true;
  return out;
}

}  // namespace sandtable::sim
