// Polhemus trackers over USB (libusb): discovery, configuration, streaming, hot-plug.
//
// UsbBackend is the libusb boundary (LibusbBackend is the real one; tests use a fake): list
// devices of vendor kPolhemusVendorId, open one, bulk write/read. PolhemusUsbSource is the
// state machine on top of it:
//   kNoDevice --(rescan finds a device; Open ok)--> kConnecting --(configuration written)-->
//   kStreaming --(read fails: unplugged)--> kNoDevice (rescans every rescan_period)
// so a tracker unplugged and plugged back in resumes without a restart (polling, which also
// works where libusb has no hotplug support). With no device it says so once (WARNING, then
// DEBUG) and keeps polling; nothing aborts. Models: vendor 0x0f44 and product 0xff20 (Liberty
// family, VRPN's Liberty Latus driver) are checked against VRPN; the other product ids are not
// (docs/tracker-formats.md); an unknown product of the vendor is still tried, named
// "Polhemus 0x....". Endpoints: bulk OUT 0x04, bulk IN 0x88 (VRPN vrpn_Tracker_LibertyHS.h).
// G4 and FASTRAK USB are discovered and named, but their record formats differ from the
// P-frame layout (FASTRAK's binary record, per VRPN's vrpn_Tracker_Fastrak.C, starts with '0'
// and an ASCII station): they report kError with that message.
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "coordinator/tracker/polhemus_records.h"
#include "coordinator/tracker/tracker_source.h"

namespace sandtable::coordinator {

constexpr uint16_t kPolhemusVendorId = 0x0F44;
constexpr unsigned char kPolhemusEndpointOut = 0x04;  // bulk OUT (host -> device)
constexpr unsigned char kPolhemusEndpointIn = 0x88;   // bulk IN (device -> host)

enum class PolhemusModel { kLiberty, kLibertyHs, kPatriot, kPatriotHs, kFastrakUsb, kG4, kUnknown };
const char* PolhemusModelName(PolhemusModel model);
// Model from the USB product id (table in docs/tracker-formats.md; unverified).
PolhemusModel PolhemusModelFromProductId(uint16_t product_id);
bool ModelSpeaksPFrames(PolhemusModel model);

struct UsbDeviceInfo {
  uint16_t vendor_id = 0;
  uint16_t product_id = 0;
  uint8_t bus = 0;
  uint8_t address = 0;
};

class UsbBackend {
 public:
  virtual ~UsbBackend() = default;
  // Polhemus devices present now (vendor 0x0F44). UNAVAILABLE if USB itself is unusable.
  virtual Expected<std::vector<UsbDeviceInfo>> Enumerate() = 0;
  virtual Status Open(const UsbDeviceInfo& device) = 0;
  virtual Status Write(std::string_view bytes) = 0;
  // Bytes read within `timeout` (maybe none). UNAVAILABLE when the device is gone.
  virtual Expected<std::string> Read(std::chrono::milliseconds timeout) = 0;
  virtual void Close() = 0;
};

// The real backend (libusb-1.0). Creating it never fails; a libusb_init failure surfaces as
// UNAVAILABLE from Enumerate().
std::unique_ptr<UsbBackend> MakeLibusbBackend();

struct PolhemusUsbOptions {
  PolhemusFormat format;
  std::chrono::milliseconds rescan_period{1000};
  std::chrono::milliseconds read_timeout{1};
  double nominal_rate_hz = 240.0;
  Status Check() const;
};

class PolhemusUsbSource : public TrackerSource {
 public:
  PolhemusUsbSource(std::unique_ptr<UsbBackend> backend, PolhemusUsbOptions options = {});
  ~PolhemusUsbSource() override;

  Status Poll(TrackerClock::time_point now, std::vector<TrackerSample>* out) override;
  TrackerState state() const override { return state_; }
  std::string Describe() const override;
  double rate_hz() const override { return options_.nominal_rate_hz; }

  const std::string& last_message() const { return message_; }
  int connections() const { return connections_; }  // successful (re)connections
  const PolhemusParserCounters& parser_counters() const { return parser_.counters(); }

 private:
  void Disconnect(const std::string& why);

  std::unique_ptr<UsbBackend> backend_;
  PolhemusUsbOptions options_;
  PolhemusRecordParser parser_;
  TrackerState state_ = TrackerState::kNoDevice;
  std::optional<TrackerClock::time_point> last_scan_;
  std::optional<UsbDeviceInfo> device_;
  PolhemusModel model_ = PolhemusModel::kUnknown;
  std::string message_ = "not scanned yet";
  bool warned_no_device_ = false;
  int connections_ = 0;
};

}  // namespace sandtable::coordinator
