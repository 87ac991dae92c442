#include "coordinator/tracker/polhemus_usb.h"

#include <libusb.h>

#include <cstdio>

#include "common/base/log.h"

namespace sandtable::coordinator {
namespace {

// Bulk endpoints of VRPN's vrpn_Tracker_LibertyHS.h (product 0xff20): OUT 0x04, IN 0x88.
constexpr unsigned char kEndpointOut = kPolhemusEndpointOut;
constexpr unsigned char kEndpointIn = kPolhemusEndpointIn;
constexpr int kReadChunkBytes = 4096;

std::string Hex(uint16_t v) {
  char text[8];
  std::snprintf(text, sizeof(text), "0x%04x", v);
  return text;
}

class LibusbBackend : public UsbBackend {
 public:
  ~LibusbBackend() override {
    Close();
    if (context_ != nullptr) libusb_exit(context_);
  }

  Expected<std::vector<UsbDeviceInfo>> Enumerate() override {
    if (context_ == nullptr) {
      const int rc = libusb_init(&context_);
      if (rc != 0) {
        context_ = nullptr;
        return UnavailableError(std::string("libusb_init failed: ") + libusb_error_name(rc));
      }
    }
    libusb_device** list = nullptr;
    const ssize_t n = libusb_get_device_list(context_, &list);
    if (n < 0) {
      return UnavailableError(std::string("libusb_get_device_list: ") +
                              libusb_error_name(static_cast<int>(n)));
    }
    std::vector<UsbDeviceInfo> out;
    for (ssize_t i = 0; i < n; ++i) {
      libusb_device_descriptor d{};
      if (libusb_get_device_descriptor(list[i], &d) != 0 || d.idVendor != kPolhemusVendorId) {
        continue;
      }
      out.push_back({d.idVendor, d.idProduct, libusb_get_bus_number(list[i]),
                     libusb_get_device_address(list[i])});
    }
    libusb_free_device_list(list, 1);
    return out;
  }

  Status Open(const UsbDeviceInfo& device) override {
    Close();
    libusb_device** list = nullptr;
    const ssize_t n = libusb_get_device_list(context_, &list);
    for (ssize_t i = 0; i < n && handle_ == nullptr; ++i) {
      if (libusb_get_bus_number(list[i]) == device.bus &&
          libusb_get_device_address(list[i]) == device.address) {
        const int rc = libusb_open(list[i], &handle_);
        if (rc != 0) {
          libusb_free_device_list(list, 1);
          handle_ = nullptr;
          return UnavailableError(std::string("libusb_open: ") + libusb_error_name(rc) +
                                  (rc == LIBUSB_ERROR_ACCESS
                                       ? " (no permission: add a udev rule for vendor 0f44)"
                                       : ""));
        }
      }
    }
    if (n >= 0) libusb_free_device_list(list, 1);
    if (handle_ == nullptr) return UnavailableError("device is gone");
    libusb_set_auto_detach_kernel_driver(handle_, 1);
    const int rc = libusb_claim_interface(handle_, 0);
    if (rc != 0) {
      Close();
      return UnavailableError(std::string("libusb_claim_interface: ") + libusb_error_name(rc));
    }
    return OkStatus();
  }

  Status Write(std::string_view bytes) override {
    if (handle_ == nullptr) return UnavailableError("not open");
    int written = 0;
    const int rc = libusb_bulk_transfer(
        handle_, kEndpointOut, reinterpret_cast<unsigned char*>(const_cast<char*>(bytes.data())),
        static_cast<int>(bytes.size()), &written, 1000);
    if (rc != 0) return UnavailableError(std::string("bulk write: ") + libusb_error_name(rc));
    return OkStatus();
  }

  Expected<std::string> Read(std::chrono::milliseconds timeout) override {
    if (handle_ == nullptr) return UnavailableError("not open");
    std::string buffer(kReadChunkBytes, '\0');
    int got = 0;
    const int rc = libusb_bulk_transfer(
        handle_, kEndpointIn, reinterpret_cast<unsigned char*>(buffer.data()), kReadChunkBytes,
        &got, static_cast<unsigned>(std::max<int64_t>(1, timeout.count())));
    if (rc != 0 && rc != LIBUSB_ERROR_TIMEOUT) {
      return UnavailableError(std::string("bulk read: ") + libusb_error_name(rc));
    }
    buffer.resize(static_cast<size_t>(got));
    return buffer;
  }

  void Close() override {
    if (handle_ != nullptr) {
      libusb_release_interface(handle_, 0);
      libusb_close(handle_);
      handle_ = nullptr;
    }
  }

 private:
  libusb_context* context_ = nullptr;
  libusb_device_handle* handle_ = nullptr;
};

}  // namespace

const char* PolhemusModelName(PolhemusModel model) {
  switch (model) {
    case PolhemusModel::kLiberty:
      return "Liberty / Liberty Latus";
    case PolhemusModel::kLibertyHs:
      return "Liberty HS";
    case PolhemusModel::kPatriot:
      return "Patriot";
    case PolhemusModel::kPatriotHs:
      return "Patriot HS";
    case PolhemusModel::kFastrakUsb:
      return "FASTRAK USB";
    case PolhemusModel::kG4:
      return "G4";
    case PolhemusModel::kUnknown:
      break;
  }
  return "unknown Polhemus model";
}

PolhemusModel PolhemusModelFromProductId(uint16_t product_id) {
  // 0xff20: VRPN's vrpn_Tracker_LibertyHS.h (Liberty Latus, the Liberty family's P-frames).
  // The others: not in VRPN, not verified against hardware (docs/tracker-formats.md).
  switch (product_id) {
    case 0xff20:
      return PolhemusModel::kLiberty;
    case 0xff12:
      return PolhemusModel::kLibertyHs;
    case 0xef20:
      return PolhemusModel::kPatriot;
    case 0xef12:
      return PolhemusModel::kPatriotHs;
    case 0x0002:
      return PolhemusModel::kFastrakUsb;
    case 0x0ef4:
      return PolhemusModel::kG4;
    default:
      return PolhemusModel::kUnknown;
  }
}

bool ModelSpeaksPFrames(PolhemusModel model) {
  return model == PolhemusModel::kLiberty || model == PolhemusModel::kLibertyHs ||
         model == PolhemusModel::kPatriot || model == PolhemusModel::kPatriotHs ||
         model == PolhemusModel::kUnknown;
}

std::unique_ptr<UsbBackend> MakeLibusbBackend() { return std::make_unique<LibusbBackend>(); }

Status PolhemusUsbOptions::Check() const {
  ST_RETURN_IF_ERROR(format.Check());
  if (rescan_period.count() <= 0) return InvalidArgumentError("polhemus: rescan_period <= 0");
  if (!(nominal_rate_hz > 0.0)) return InvalidArgumentError("polhemus: nominal_rate_hz <= 0");
  return OkStatus();
}

PolhemusUsbSource::PolhemusUsbSource(std::unique_ptr<UsbBackend> backend,
                                     PolhemusUsbOptions options)
    : backend_(std::move(backend)), options_(std::move(options)), parser_(options_.format) {
  ST_CHECK(options_.Check().ok()) << options_.Check().ToString();
}

PolhemusUsbSource::~PolhemusUsbSource() {
  if (device_) backend_->Close();
}

void PolhemusUsbSource::Disconnect(const std::string& why) {
  backend_->Close();
  device_.reset();
  parser_.Finish();
  parser_ = PolhemusRecordParser(options_.format);
  state_ = TrackerState::kNoDevice;
  message_ = why;
  warned_no_device_ = false;
  ST_LOG(kWarning) << "tracker: " << why << "; waiting for it to come back";
}

Status PolhemusUsbSource::Poll(TrackerClock::time_point now, std::vector<TrackerSample>* out) {
  if (state_ == TrackerState::kNoDevice || state_ == TrackerState::kError) {
    if (last_scan_ && now - *last_scan_ < options_.rescan_period) return OkStatus();
    last_scan_ = now;
    Expected<std::vector<UsbDeviceInfo>> found = backend_->Enumerate();
    if (!found.ok() || found->empty()) {
      message_ = found.ok() ? "no Polhemus tracker (USB vendor 0x0f44) found"
                            : "USB unusable: " + found.status().message();
      if (!warned_no_device_) {
        ST_LOG(kWarning) << "tracker: " << message_ << "; the coordinator runs on without it "
                         << "and keeps looking every " << options_.rescan_period.count() << " ms";
        warned_no_device_ = true;
      }
      state_ = TrackerState::kNoDevice;
      return OkStatus();
    }
    const UsbDeviceInfo device = found->front();
    model_ = PolhemusModelFromProductId(device.product_id);
    const std::string name =
        std::string(PolhemusModelName(model_)) + " (product " + Hex(device.product_id) + ")";
    if (!ModelSpeaksPFrames(model_)) {
      state_ = TrackerState::kError;
      message_ = name +
                 " found, but its record format is not implemented (only the "
                 "Liberty/Patriot binary P-frame layout is)";
      if (!warned_no_device_) ST_LOG(kWarning) << "tracker: " << message_;
      warned_no_device_ = true;
      return OkStatus();
    }
    state_ = TrackerState::kConnecting;
    Status opened = backend_->Open(device);
    if (!opened.ok()) {
      state_ = TrackerState::kNoDevice;
      message_ = name + ": " + opened.message();
      ST_LOG(kWarning) << "tracker: " << message_;
      return OkStatus();
    }
    for (const std::string& command : options_.format.ConfigurationCommands()) {
      Status written = backend_->Write(command);
      if (!written.ok()) {
        Disconnect(name + ": configuration failed: " + written.message());
        return OkStatus();
      }
    }
    device_ = device;
    state_ = TrackerState::kStreaming;
    message_ = name + " streaming";
    ++connections_;
    ST_LOG(kInfo) << "tracker: " << message_;
  }
  if (state_ != TrackerState::kStreaming) return OkStatus();
  // Drain what is there (bounded, so a babbling device cannot starve the coordinator).
  for (int reads = 0; reads < 8; ++reads) {
    Expected<std::string> bytes = backend_->Read(options_.read_timeout);
    if (!bytes.ok()) {
      Disconnect("tracker unplugged or failed (" + bytes.status().message() + ")");
      return OkStatus();
    }
    if (bytes->empty()) break;
    parser_.Feed(*bytes, out);
  }
  return OkStatus();
}

std::string PolhemusUsbSource::Describe() const {
  return std::string("polhemus usb: ") + TrackerStateName(state_) + ": " + message_;
}

}  // namespace sandtable::coordinator
