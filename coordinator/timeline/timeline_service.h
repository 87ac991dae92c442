// TimelineService: the after-action review timeline on the coordinator (CoordinatorService).
//
// Requests on the ROUTER: play, pause, seek, rate (proto/timeline.proto) -> timeline_reply
// {request_sequence, accepted, reason, clock}. Events: timeline_clock at
// publish_rate_hz and at once after every change (accepted request, end reached). The clock
// carries media time sampled at the coordinator's steady clock (sample_time_ns), rate and the
// playing flag, so nodes extrapolate between events with their time-sync offset, plus the
// position of every track at that media time. Rules of the clock: media_clock.h.
#pragma once

#include <cstdint>

#include "cluster/media_clock.h"
#include "cluster/personnel_tracks.h"
#include "coordinator/membership/coordinator_server.h"
#include "proto/timeline.pb.h"

namespace sandtable::coordinator {

using cluster::PersonnelTracks;
using cluster::TrackPositionAt;
using cluster::TrackSample;

struct TimelineServiceOptions {
  double publish_rate_hz = 30.0;
  double max_rate = 64.0;
  Status Check() const;
};

struct TimelineCounters {
  uint64_t accepted = 0;
  uint64_t rejected = 0;
  uint64_t clocks_published = 0;
};

class TimelineService : public CoordinatorService {
 public:
  TimelineService(PersonnelTracks tracks, TimelineServiceOptions options = {});

  bool Serves(wire::Envelope::BodyCase body) const override;
  void OnRequest(net::Incoming request, CoordinatorServer& server) override;
  Status OnStep(CoordinatorServer& server) override;

  // The clock as published at now_ns (tracks filled in).
  wire::TimelineClock ClockAt(int64_t now_ns) const;

  const PersonnelTracks& tracks() const { return tracks_; }
  const cluster::MediaClock& clock() const { return clock_; }
  const TimelineCounters& counters() const { return counters_; }

 private:
  Status PublishClock(CoordinatorServer& server, int64_t now_ns);

  PersonnelTracks tracks_;
  TimelineServiceOptions options_;
  cluster::MediaClock clock_;
  TimelineCounters counters_;
  int64_t last_publish_ns_ = 0;
};

}  // namespace sandtable::coordinator
