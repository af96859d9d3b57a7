#include "server/store/postgres_change_feed.h"

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <pqxx/pqxx>
#include <thread>
#include <utility>

namespace drillbif::server {
namespace {

class PostgresChangeFeed final : public JobChangeFeed {
 public:
  PostgresChangeFeed(std::string conninfo, std::function<void(std::string_view)> log,
                     JobChangeCallback on_change)
      : conninfo_(std::move(conninfo)), log_(std::move(log)), on_change_(std::move(on_change)) {}

  ~PostgresChangeFeed() override {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopping_ = true;
    }
    cv_.notify_all();
    if (thread_.joinable()) thread_.join();
  }

  // The first connection, on the caller's thread (so that Open reports a failure), then the
  // thread.
  Status Start() {
    try {
      Connect();
    } catch (const std::exception& error) {
      Log(std::string("job store change feed: cannot connect: ") + error.what());
      return Unavailable("the job store's change feed cannot connect to the database");
    }
    thread_ = std::thread([this] { Loop(); });
    return Status::Ok();
  }

 private:
  // Hands each notice of the channel to the feed.
  class Receiver final : public pqxx::notification_receiver {
   public:
    Receiver(pqxx::connection_base& connection, PostgresChangeFeed* feed)
        : pqxx::notification_receiver(connection, kJobsChannel), feed_(feed) {}
    void operator()(const std::string& payload, int /*backend_pid*/) override {
      feed_->Deliver(ParseJobNotice(payload));
    }

   private:
    PostgresChangeFeed* const feed_;
  };

  // Opens the connection and LISTENs (the receiver's constructor runs LISTEN). Throws.
  void Connect() {
    auto connection = std::make_unique<pqxx::connection>(conninfo_);
    auto receiver = std::make_unique<Receiver>(*connection, this);
    connection_ = std::move(connection);
    receiver_ = std::move(receiver);
  }

  // Drops the connection without a round trip: disconnecting first keeps the receiver's
  // destructor from sending UNLISTEN (the session's end ends the LISTEN anyway), which on a
  // broken connection would make libpqxx try to reconnect.
  void Disconnect() {
    if (connection_) connection_->disconnect();
    receiver_.reset();
    connection_.reset();
  }

  void Loop() {
    int retry_ms = kFeedRetryFirstMs;
    for (;;) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (stopping_) break;
      }
      if (!connection_) {
        try {
          Connect();
        } catch (const std::exception& error) {
          Log(std::string("job store change feed: reconnect failed, next attempt in ") +
              std::to_string(retry_ms) + " ms: " + error.what());
          Disconnect();
          std::unique_lock<std::mutex> lock(mutex_);
          cv_.wait_for(lock, std::chrono::milliseconds(retry_ms), [this] { return stopping_; });
          retry_ms = std::min(2 * retry_ms, kFeedRetryMaxMs);
          continue;
        }
        retry_ms = kFeedRetryFirstMs;
        Log("job store change feed: reconnected; everything is read again");
        // Notices sent while the feed was away are lost: the listeners read everything again.
        Deliver(JobChange{JobChange::Kind::kResync, ""});
        continue;
      }
      try {
        // Delivers the notices that arrive (through Receiver) within the slice.
        connection_->await_notification(0, kFeedWaitMs * 1000L);
        if (!connection_->is_open()) throw pqxx::broken_connection("the connection closed");
      } catch (const std::exception& error) {
        Log(std::string("job store change feed: connection lost, reconnecting: ") + error.what());
        Disconnect();
      }
    }
    Disconnect();
  }

  void Deliver(const JobChange& change) {
    try {
      on_change_(change);
    } catch (const std::exception& error) {
      // The callback must not throw; if it does, the feed goes on with the next notice.
      Log(std::string("job store change feed: a listener threw: ") + error.what());
    } catch (...) {
      Log("job store change feed: a listener threw");
    }
  }

  void Log(const std::string& line) const {
    if (log_) log_(line);
  }

  const std::string conninfo_;
  const std::function<void(std::string_view)> log_;
  const JobChangeCallback on_change_;
  // The feed's thread only (after Start).
  std::unique_ptr<pqxx::connection> connection_;
  std::unique_ptr<Receiver> receiver_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool stopping_ = false;
  std::thread thread_;
};

}  // namespace

JobChange ParseJobNotice(std::string_view payload) {
  if (payload.size() > 2 && payload[1] == ':') {
    if (payload[0] == 'q') return {JobChange::Kind::kQueued, std::string(payload.substr(2))};
    if (payload[0] == 'c') return {JobChange::Kind::kChanged, std::string(payload.substr(2))};
  }
  return {JobChange::Kind::kChanged, std::string(payload)};
}

StatusOr<std::unique_ptr<JobChangeFeed>> OpenPostgresChangeFeed(
    const std::string& conninfo, std::function<void(std::string_view)> log,
    JobChangeCallback on_change) {
  if (!on_change) return InvalidArgument("on_change: must be set");
  auto feed = std::make_unique<PostgresChangeFeed>(conninfo, std::move(log), std::move(on_change));
  DRILLBIF_RETURN_IF_ERROR(feed->Start());
  return std::unique_ptr<JobChangeFeed>(std::move(feed));
}

}  // namespace drillbif::server
