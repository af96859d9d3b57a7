// The PostgreSQL store's change feed (JobStore::OpenChangeFeed; internal to server/store/).
//
// The jobs table's triggers (postgres_job_store.cc, schema version 3) send
// pg_notify('drillbif_jobs', payload) for every job that is inserted or changes what a watcher
// reads, in the transaction that makes the change: PostgreSQL delivers the notice to every
// listening session when (and only if) that transaction commits. The payload is the job's id
// prefixed with "q:" when the job became claimable (a submit or a requeue) and "c:" otherwise.
//
// The feed holds a connection of its own (a session that LISTENs cannot run the store's
// transactions: notices are held back while a transaction is open) and a thread that waits on
// it in slices of kFeedWaitMs, so that its destructor returns within about that long. A lost
// connection is opened again with a back-off (kFeedRetryFirstMs doubling to kFeedRetryMaxMs);
// once it is back the feed reports JobChange::kResync, since notices sent meanwhile are lost.
#ifndef DRILLBIF_SERVER_STORE_POSTGRES_CHANGE_FEED_H_
#define DRILLBIF_SERVER_STORE_POSTGRES_CHANGE_FEED_H_

#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// The channel the jobs table's triggers notify.
inline constexpr const char* kJobsChannel = "drillbif_jobs";
// Longest wait for a notice before the feed's thread checks whether it must stop. Milliseconds.
inline constexpr int kFeedWaitMs = 50;
// First and longest wait between two attempts to reconnect a lost feed. Milliseconds.
inline constexpr int kFeedRetryFirstMs = 100;
inline constexpr int kFeedRetryMaxMs = 5000;

// Connects to `conninfo` (a libpq connection string, password included), LISTENs on
// kJobsChannel and starts the feed's thread, which calls `on_change` per notice. `log` gets one
// line per connection loss and recovery (never the password: the connection string is not
// logged). UNAVAILABLE when the first connection fails.
StatusOr<std::unique_ptr<JobChangeFeed>> OpenPostgresChangeFeed(
    const std::string& conninfo, std::function<void(std::string_view)> log,
    JobChangeCallback on_change);

// The change a notice's payload describes ("q:<id>", "c:<id>"); kChanged with the whole payload
// as the id for a payload of neither form (the feed passes it on rather than drop it).
JobChange ParseJobNotice(std::string_view payload);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_POSTGRES_CHANGE_FEED_H_
