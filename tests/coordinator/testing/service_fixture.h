// A real CoordinatorServer on loopback serving one service, with a SUB on its events and a
// DEALER on its requests: the fixture of the coordinator services' tests.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <thread>

#include <gtest/gtest.h>

#include "coordinator/membership/coordinator_server.h"
#include "net/channel.h"

namespace sandtable::coordinator::testing {

class ServiceFixture : public ::testing::Test {
 protected:
  // Starts the server with `service` (owned by the derived fixture) and connects both sockets.
  void StartWith(CoordinatorService* service) {
    CoordinatorOptions options;
    options.step_period = std::chrono::milliseconds(5);
    server_ = std::make_unique<CoordinatorServer>(options);
    server_->AddService(service);
    ASSERT_TRUE(server_->Start().ok());
    thread_ = std::thread([this] { (void)server_->Run(stop_); });
    auto sub = net::Socket::Create(&context_, net::SocketType::kEventSubscriber);
    ASSERT_TRUE(sub.ok());
    ASSERT_TRUE((*sub)->Connect(server_->event_endpoint()).ok());
    sub_ = std::make_unique<net::Channel>(std::move(*sub), 901, 1, &counters_);
    auto dealer = net::Socket::Create(&context_, net::SocketType::kDealer);
    ASSERT_TRUE(dealer.ok());
    ASSERT_TRUE((*dealer)->Connect(server_->request_endpoint()).ok());
    dealer_ = std::make_unique<net::Channel>(std::move(*dealer), 902, 1, &counters_);
  }
  void TearDown() override {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }

  std::unique_ptr<CoordinatorServer> server_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  zmq::context_t context_;
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> sub_, dealer_;
};

}  // namespace sandtable::coordinator::testing
