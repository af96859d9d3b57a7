// The PostgreSQL JobStore: connecting, the schema, errors, the job life cycle, listing and
// stats. Results are in postgres_store_results.cc, health and retention in
// postgres_store_maintenance.cc. Semantics: job_store.h and docs/store.md.
#include "server/store/postgres_job_store.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <iterator>
#include <memory>
#include <optional>
#include <pqxx/pqxx>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "drillbif/common/checked.h"
#include "server/store/postgres_change_feed.h"
#include "server/store/postgres_store_impl.h"
#include "server/store/store_checks.h"

namespace drillbif::server {
namespace {

// The schema, created in one transaction by the first Open on an empty database. The columns
// are the SQLite store's (sqlite_job_store.cc has what each means); seq is an identity column
// (never reused: page tokens stay meaningful after deletions). result_chunks' primary key is the
// index page reads walk.
constexpr const char* kSchema = R"sql(
CREATE TABLE jobs (
  seq BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
  id TEXT NOT NULL UNIQUE,
  kind TEXT NOT NULL CHECK (kind <> ''),
  state SMALLINT NOT NULL CHECK (state BETWEEN 0 AND 4),
  request BYTEA NOT NULL,
  cache_key TEXT NOT NULL,
  request_id TEXT UNIQUE,
  shares TEXT REFERENCES jobs(id) ON DELETE SET NULL,
  result_key TEXT NOT NULL,
  progress DOUBLE PRECISION NOT NULL DEFAULT 0,
  current_value DOUBLE PRECISION,
  points BIGINT NOT NULL DEFAULT 0,
  error_code INTEGER NOT NULL DEFAULT 0,
  error_message TEXT NOT NULL DEFAULT '',
  created_ms BIGINT NOT NULL,
  started_ms BIGINT NOT NULL DEFAULT 0,
  finished_ms BIGINT NOT NULL DEFAULT 0,
  cache_hit BOOLEAN NOT NULL DEFAULT FALSE,
  attempts INTEGER NOT NULL DEFAULT 0,
  cancel_requested BOOLEAN NOT NULL DEFAULT FALSE,
  worker_id TEXT NOT NULL DEFAULT '',
  client TEXT NOT NULL DEFAULT '',
  lane INTEGER NOT NULL DEFAULT 0 CHECK (lane >= 0),
  run BIGINT NOT NULL DEFAULT 0,
  streamed_items BIGINT NOT NULL DEFAULT 0,
  streamed_bytes BIGINT NOT NULL DEFAULT 0,
  lease_expires_ms BIGINT NOT NULL DEFAULT 0
);
CREATE INDEX jobs_by_state ON jobs(state, seq);
CREATE INDEX jobs_by_cache_key ON jobs(cache_key, seq) WHERE cache_key <> '';
CREATE INDEX jobs_by_shares ON jobs(shares) WHERE shares IS NOT NULL;
CREATE INDEX jobs_by_result_key ON jobs(result_key);
CREATE INDEX jobs_claimable ON jobs(client, lane, seq) WHERE state = 0 AND shares IS NULL;
CREATE INDEX jobs_running ON jobs(client, lane) WHERE state = 1 AND shares IS NULL;
CREATE INDEX jobs_finished ON jobs(finished_ms, seq) WHERE state IN (2, 3, 4);
CREATE INDEX jobs_leased ON jobs(lease_expires_ms) WHERE state = 1 AND lease_expires_ms > 0;
CREATE TABLE results (
  result_key TEXT PRIMARY KEY,
  data BYTEA NOT NULL,
  points BIGINT NOT NULL,
  created_ms BIGINT NOT NULL,
  run_id TEXT NOT NULL DEFAULT '',
  items BIGINT NOT NULL DEFAULT 0,
  bytes BIGINT NOT NULL DEFAULT 0
);
CREATE TABLE result_chunks (
  run_id TEXT NOT NULL,
  stream INTEGER NOT NULL CHECK (stream >= 0),
  first_item BIGINT NOT NULL CHECK (first_item >= 0),
  item_count BIGINT NOT NULL CHECK (item_count >= 1),
  data BYTEA NOT NULL,
  PRIMARY KEY (run_id, stream, first_item)
);
CREATE TABLE counters (
  name TEXT PRIMARY KEY,
  value BIGINT NOT NULL
);
INSERT INTO counters(name, value) VALUES ('cache_hits', 0), ('probes', 0);
)sql";

// Migrations after version 1 (kSchema), in order: entry i brings the schema from version i + 1
// to i + 2. Configure applies the missing ones in its transaction, a new database included, so
// that every database has gone through the same steps. Never edit one once released: append one.
constexpr const char* kMigrations[] = {
    // 1 -> 2: child jobs (as the SQLite store's migration 3 -> 4, which says what each is for).
    R"sql(
ALTER TABLE jobs ADD COLUMN parent_id TEXT NOT NULL DEFAULT '';
DROP INDEX jobs_claimable;
CREATE INDEX jobs_claimable ON jobs(client, lane, seq)
  WHERE state = 0 AND shares IS NULL AND parent_id = '';
CREATE INDEX jobs_by_parent ON jobs(parent_id, state, seq) WHERE parent_id <> '';
CREATE INDEX jobs_queued_children ON jobs(seq) WHERE state = 0 AND parent_id <> '';
)sql",
    // 2 -> 3: change notices (postgres_change_feed.h). Every inserted job, and every job whose
    // update changes what a watcher reads (the columns of the WHEN clause: not the lease's
    // heartbeat or the streamed counts, which change often and show nowhere), notifies
    // 'drillbif_jobs' with its id: "q:<id>" when it became claimable (QUEUED and running
    // itself, after a submit or a requeue: idle workers look), "c:<id>" otherwise. Deletions
    // notify nothing. The notice leaves with the transaction's commit, so a listener reads the
    // change it announces. Written to be run again (OR REPLACE, IF EXISTS), so that a database
    // taken back to an older version by hand migrates again.
    R"sql(
CREATE OR REPLACE FUNCTION drillbif_notify_job() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
  IF NEW.state = 0 AND NEW.shares IS NULL
      AND (TG_OP = 'INSERT' OR OLD.state <> 0 OR OLD.shares IS NOT NULL) THEN
    PERFORM pg_notify('drillbif_jobs', 'q:' || NEW.id);
  ELSE
    PERFORM pg_notify('drillbif_jobs', 'c:' || NEW.id);
  END IF;
  RETURN NULL;
END
$$;
DROP TRIGGER IF EXISTS jobs_notify_insert ON jobs;
CREATE TRIGGER jobs_notify_insert AFTER INSERT ON jobs
  FOR EACH ROW EXECUTE FUNCTION drillbif_notify_job();
DROP TRIGGER IF EXISTS jobs_notify_update ON jobs;
CREATE TRIGGER jobs_notify_update AFTER UPDATE ON jobs FOR EACH ROW
  WHEN (OLD.state IS DISTINCT FROM NEW.state OR OLD.progress IS DISTINCT FROM NEW.progress
        OR OLD.current_value IS DISTINCT FROM NEW.current_value
        OR OLD.points IS DISTINCT FROM NEW.points OR OLD.started_ms IS DISTINCT FROM NEW.started_ms
        OR OLD.finished_ms IS DISTINCT FROM NEW.finished_ms
        OR OLD.attempts IS DISTINCT FROM NEW.attempts OR OLD.shares IS DISTINCT FROM NEW.shares
        OR OLD.cache_hit IS DISTINCT FROM NEW.cache_hit)
  EXECUTE FUNCTION drillbif_notify_job();
)sql",
};
static_assert(std::size(kMigrations) == PostgresJobStore::kSchemaVersion - 1,
              "one migration per schema version after the first");

// Columns of a JobRecord, in the order ReadJob expects; %s is the request expression.
constexpr const char* kJobColumns =
    "seq, id, kind, state, %s, cache_key, request_id, shares, progress, current_value, points, "
    "error_code, error_message, created_ms, started_ms, finished_ms, cache_hit, attempts, "
    "cancel_requested, worker_id, client, lane, run, lease_expires_ms, parent_id";

std::string SelectJobs(const char* request_expression, const char* rest) {
  char columns[512];
  std::snprintf(columns, sizeof(columns), kJobColumns, request_expression);
  return std::string("SELECT ") + columns + " FROM jobs " + rest;
}

// A TEXT column that may be NULL ("" then).
std::string Text(const pqxx::field& f) { return f.is_null() ? std::string() : f.as<std::string>(); }

JobRecord ReadJob(const pqxx::row& r) {
  JobRecord job;
  job.id = r[1].as<std::string>();
  job.kind = r[2].as<std::string>();
  job.state = static_cast<JobState>(r[3].as<int>());
  job.request = pqxx::binarystring(r[4]).str();
  job.cache_key = r[5].as<std::string>();
  job.request_id = Text(r[6]);
  job.shared_with = Text(r[7]);
  job.progress = r[8].as<double>();
  if (!r[9].is_null()) job.current_value = r[9].as<double>();
  job.points = r[10].as<int64_t>();
  job.error_code = static_cast<StatusCode>(r[11].as<int>());
  job.error_message = r[12].as<std::string>();
  job.created_ms = r[13].as<int64_t>();
  job.started_ms = r[14].as<int64_t>();
  job.finished_ms = r[15].as<int64_t>();
  job.cache_hit = r[16].as<bool>();
  job.attempts = r[17].as<int>();
  job.cancel_requested = r[18].as<bool>();
  job.worker_id = r[19].as<std::string>();
  job.client = r[20].as<std::string>();
  job.lane = r[21].as<int>();
  job.run = r[22].as<int64_t>();
  job.lease_expires_ms = r[23].as<int64_t>();
  job.parent = r[24].as<std::string>();
  return job;
}

pqxx::binarystring Bytes(std::string_view bytes) {
  return pqxx::binarystring(bytes.data(), bytes.size());
}

// `uri` with the password added: as a percent-encoded query parameter of a URI, or as a quoted
// key=value pair.
std::string WithPassword(const std::string& uri, const std::string& password) {
  if (password.empty()) return uri;
  if (uri.rfind("postgresql://", 0) == 0 || uri.rfind("postgres://", 0) == 0) {
    std::string encoded;
    for (const unsigned char c : password) {
      if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~') {
        encoded += static_cast<char>(c);
      } else {
        char hex[4];
        std::snprintf(hex, sizeof(hex), "%%%02X", c);
        encoded += hex;
      }
    }
    return uri + (uri.find('?') == std::string::npos ? "?" : "&") + "password=" + encoded;
  }
  std::string quoted;
  for (const char c : password) {
    if (c == '\\' || c == '\'') quoted += '\\';
    quoted += c;
  }
  return uri + " password='" + quoted + "'";
}

}  // namespace

void PostgresStoreImpl::Log(const std::string& line) const {
  if (options_.log) options_.log(line);
}

pqxx::connection& PostgresStoreImpl::Connection() {
  if (!connection_ || !connection_->is_open()) {
    connection_.reset();
    // Kept only once configured: a failure here leaves no half-set connection to reuse.
    auto opened = std::make_unique<pqxx::connection>(WithPassword(uri_, options_.password));
    {
      pqxx::nontransaction session(*opened);
      session.exec("SET idle_in_transaction_session_timeout = " +
                   std::to_string(options_.idle_in_transaction_timeout_ms));
    }
    connection_ = std::move(opened);
  }
  return *connection_;
}

Status PostgresStoreImpl::Error(const char* what, const std::exception& error) {
  Log(std::string("job store: ") + what + ": " + error.what());
  if (dynamic_cast<const pqxx::broken_connection*>(&error) != nullptr) {
    connection_.reset();
    fault_ = Unavailable(std::string("the job store's database is unreachable (") + what + ")");
    return fault_;
  }
  if (const auto* sql = dynamic_cast<const pqxx::sql_error*>(&error)) {
    const std::string& state = sql->sqlstate();
    if (state == "53100") {  // disk_full
      fault_ = ResourceExhausted(std::string("the job store's disk is full (") + what + ")");
      return fault_;
    }
    if (state.rfind("53", 0) == 0 || state.rfind("57", 0) == 0 || state.rfind("08", 0) == 0) {
      // Insufficient resources, operator intervention (shutdown), connection exceptions.
      connection_.reset();
      fault_ = Unavailable(std::string("the job store's database is unavailable (") + what + ")");
      return fault_;
    }
    if (state == "54000") {  // program_limit_exceeded: a value beyond what a row holds
      return InvalidArgument(std::string(what) + ": a value is larger than the job store accepts");
    }
  }
  return Internal(std::string("the job store failed to ") + what);
}

Status PostgresStoreImpl::Configure() {
  return WriteStatus("create the schema", [&](Tx& tx) -> Status {
    tx.exec("CREATE TABLE IF NOT EXISTS drillbif_schema (version INTEGER NOT NULL)");
    const pqxx::result r = tx.exec("SELECT version FROM drillbif_schema");
    if (r.size() > 1) return FailedPrecondition("not a drillbif job store (drillbif_schema)");
    const int version = r.empty() ? 0 : r[0][0].as<int>();
    if (version > PostgresJobStore::kSchemaVersion) {
      return FailedPrecondition("job store schema version " + std::to_string(version) +
                                " is newer than this build supports (" +
                                std::to_string(PostgresJobStore::kSchemaVersion) +
                                "); use a newer drillbif-server");
    }
    if (version == 0) {
      tx.exec(kSchema);
      tx.exec("INSERT INTO drillbif_schema (version) VALUES (1)");
    }
    for (int v = std::max(version, 1); v < PostgresJobStore::kSchemaVersion; ++v) {
      tx.exec(kMigrations[v - 1]);
    }
    if (version < PostgresJobStore::kSchemaVersion) {
      tx.exec_params("UPDATE drillbif_schema SET version = $1", PostgresJobStore::kSchemaVersion);
    }
    return Status::Ok();
  });
}

StatusOr<JobHead> PostgresStoreImpl::Head(Tx& tx, std::string_view id) {
  const pqxx::result r = tx.exec_params(
      "SELECT state, shares IS NOT NULL, cancel_requested, attempts, result_key, run, "
      "streamed_items, streamed_bytes FROM jobs WHERE id = $1",
      std::string(id));
  if (r.empty()) return NoJob(id);
  JobHead head;
  head.state = r[0][0].as<int>();
  head.shares = r[0][1].as<bool>();
  head.cancel_requested = r[0][2].as<bool>();
  head.attempts = r[0][3].as<int>();
  head.result_key = r[0][4].as<std::string>();
  head.run = r[0][5].as<int64_t>();
  head.streamed_items = r[0][6].as<int64_t>();
  head.streamed_bytes = r[0][7].as<int64_t>();
  return head;
}

StatusOr<JobHead> PostgresStoreImpl::RunningHead(Tx& tx, std::string_view id, const char* action,
                                                 int64_t run) {
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(tx, id));
  DRILLBIF_RETURN_IF_ERROR(CheckRunning(id, action, run, head));
  return head;
}

Status PostgresStoreImpl::PromoteFollower(Tx& tx, std::string_view id) {
  const pqxx::result r = tx.exec_params(
      "SELECT id FROM jobs WHERE shares = $1 AND state IN (0, 1) ORDER BY seq LIMIT 1",
      std::string(id));
  if (r.empty()) return Status::Ok();
  const std::string next = r[0][0].as<std::string>();
  tx.exec_params(
      "UPDATE jobs SET shares = NULL, state = 0, started_ms = 0, progress = 0, "
      "current_value = NULL, points = 0 WHERE id = $1",
      next);
  tx.exec_params(
      "UPDATE jobs SET shares = $2, state = 0, started_ms = 0, progress = 0, "
      "current_value = NULL, points = 0 WHERE shares = $1 AND state IN (0, 1)",
      std::string(id), next);
  return Status::Ok();
}

Status PostgresStoreImpl::RequeueWithFollowers(Tx& tx, std::string_view id, bool count_attempt) {
  DRILLBIF_RETURN_IF_ERROR(UpdateRunning(
      tx,
      "UPDATE jobs SET state = 0, started_ms = 0, progress = 0, current_value = NULL, "
      "points = 0, worker_id = '', attempts = attempts - $2 WHERE id = $1 AND state = 1",
      id, count_attempt ? 0 : 1));
  DRILLBIF_RETURN_IF_ERROR(DropRunChunks(tx, id));
  // The next run submits its own tasks: this run's are no longer wanted.
  DRILLBIF_RETURN_IF_ERROR(CancelChildren(tx, id));
  tx.exec_params(
      "UPDATE jobs SET state = 0, started_ms = 0, progress = 0, current_value = NULL, "
      "points = 0 WHERE shares = $1 AND state IN (0, 1)",
      std::string(id));
  return Status::Ok();
}

Status PostgresStoreImpl::FailWithFollowers(Tx& tx, std::string_view id, StatusCode code,
                                            std::string_view message) {
  const int64_t now = NowMs();
  DRILLBIF_RETURN_IF_ERROR(UpdateRunning(
      tx,
      "UPDATE jobs SET state = 3, error_code = $2, error_message = $3, finished_ms = $4 "
      "WHERE id = $1 AND state = 1",
      id, static_cast<int>(code), std::string(message), now));
  DRILLBIF_RETURN_IF_ERROR(DropRunChunks(tx, id));
  DRILLBIF_RETURN_IF_ERROR(CancelChildren(tx, id));
  tx.exec_params(
      "UPDATE jobs SET state = 3, error_code = $2, error_message = $3, finished_ms = $4 "
      "WHERE shares = $1 AND state IN (0, 1)",
      std::string(id), static_cast<int>(code), std::string(message), now);
  return Status::Ok();
}

Status PostgresStoreImpl::CancelRunning(Tx& tx, std::string_view id) {
  DRILLBIF_RETURN_IF_ERROR(UpdateRunning(
      tx, "UPDATE jobs SET state = 4, finished_ms = $2 WHERE id = $1 AND state = 1", id, NowMs()));
  DRILLBIF_RETURN_IF_ERROR(DropRunChunks(tx, id));
  DRILLBIF_RETURN_IF_ERROR(CancelChildren(tx, id));
  return PromoteFollower(tx, id);
}

Status PostgresStoreImpl::CancelChildren(Tx& tx, std::string_view id) {
  // Two statements, in this order, because claims do not take the write lock. A child that a
  // claim has locked (FOR UPDATE SKIP LOCKED) makes the first statement wait for the claim's
  // commit and then skip the child, which is RUNNING by then; the second statement starts
  // after that commit (read committed: a new snapshot per statement) and asks its worker to
  // stop. A claim that comes after the first statement finds the child locked or, once this
  // transaction commits, CANCELLED (the claim's locking read re-checks the row). In the other
  // order a child claimed between the two statements would escape both: not yet RUNNING for the
  // flag, no longer QUEUED for the cancel (the contract suite's
  // ACancelThatWaitsForAClaimInProgressStopsTheClaimedChild fails that way).
  tx.exec_params(
      "UPDATE jobs SET state = 4, finished_ms = $2 WHERE parent_id = $1 AND parent_id <> '' "
      "AND state = 0",
      std::string(id), NowMs());
  tx.exec_params(
      "UPDATE jobs SET cancel_requested = TRUE WHERE parent_id = $1 AND parent_id <> '' "
      "AND state = 1",
      std::string(id));
  return Status::Ok();
}

Status PostgresStoreImpl::CheckQueueLimits(Tx& tx, const SubmitRequest& request) {
  int64_t waiting_of_client = 0;
  int64_t waiting = 0;
  if (request.max_queued_per_client > 0) {
    waiting_of_client =
        tx.exec_params(
              "SELECT COUNT(*) FROM jobs WHERE state = 0 AND shares IS NULL AND parent_id = '' "
              "AND client = $1",
              request.client)[0][0]
            .as<int64_t>();
  }
  if (request.max_queued > 0) {
    waiting =
        tx.exec("SELECT COUNT(*) FROM jobs WHERE state = 0 AND shares IS NULL AND parent_id = ''")
            [0][0]
                .as<int64_t>();
  }
  return server::CheckQueueLimits(request, waiting_of_client, waiting);
}

StatusOr<SubmitResult> PostgresStoreImpl::Submit(const SubmitRequest& request) {
  DRILLBIF_RETURN_IF_ERROR(CheckSubmit(request));
  DRILLBIF_RETURN_IF_ERROR(
      CheckSize("request", request.request.size(), PostgresJobStore::kMaxValueBytes));
  return Write<SubmitResult>("submit a job", [&](Tx& tx) -> StatusOr<SubmitResult> {
    SubmitResult result;
    if (!request.request_id.empty()) {
      const pqxx::result r = tx.exec_params(
          "SELECT id, kind, request, cache_hit, shares, parent_id FROM jobs WHERE request_id = $1",
          request.request_id);
      if (!r.empty()) {
        if (r[0][1].as<std::string>() != request.kind ||
            pqxx::binarystring(r[0][2]).str() != request.request ||
            r[0][5].as<std::string>() != request.parent) {
          return RequestIdReused(request.request_id, r[0][0].as<std::string>());
        }
        result.id = r[0][0].as<std::string>();
        result.deduplicated = true;
        result.cache_hit = r[0][3].as<bool>();
        result.shared_with = Text(r[0][4]);
        return result;
      }
    }
    if (!request.parent.empty()) {
      // Parents leave RUNNING only under the write lock, which this transaction holds: the
      // parent cannot finish between this check and the insert.
      StatusOr<JobHead> parent = Head(tx, request.parent);
      if (!parent.ok() && parent.status().code() != StatusCode::kNotFound) return parent.status();
      DRILLBIF_RETURN_IF_ERROR(
          CheckParent(request.parent, request.parent_run, parent.ok() ? &*parent : nullptr));
    }
    const int64_t now = NowMs();
    const std::string id = NewJobId(random_);
    const std::string result_key = ResultKey(request, id);
    // Values for the new row; a cache hit or a shared job starts in another state.
    int state = kQueued;
    std::string shares;
    double progress = 0;
    std::optional<double> current_value;
    int64_t points = 0, started_ms = 0, finished_ms = 0;
    if (!request.cache_key.empty()) {
      const pqxx::result r =
          tx.exec_params("SELECT points FROM results WHERE result_key = $1", result_key);
      if (!r.empty()) {
        result.cache_hit = true;
        state = kSucceeded;
        progress = 1;
        points = r[0][0].as<int64_t>();
        started_ms = finished_ms = now;
      }
    }
    if (!request.cache_key.empty() && !result.cache_hit) {
      // A job being cancelled is not shared: it would end without a result.
      const pqxx::result r = tx.exec_params(
          "SELECT id, state, started_ms, progress, current_value, points FROM jobs "
          "WHERE cache_key = $1 AND shares IS NULL AND state IN (0, 1) "
          "AND NOT cancel_requested ORDER BY seq LIMIT 1",
          request.cache_key);
      if (!r.empty()) {
        shares = r[0][0].as<std::string>();
        state = r[0][1].as<int>();
        started_ms = r[0][2].as<int64_t>();
        progress = r[0][3].as<double>();
        if (!r[0][4].is_null()) current_value = r[0][4].as<double>();
        points = r[0][5].as<int64_t>();
        result.shared_with = shares;
      }
    }
    // Only a job that will run adds work: cache hits and followers are never refused. Nor are
    // children: their parent was admitted with the cost of the whole.
    if (state == kQueued && shares.empty() && request.parent.empty()) {
      DRILLBIF_RETURN_IF_ERROR(CheckQueueLimits(tx, request));
    }
    tx.exec_params(
        "INSERT INTO jobs (id, kind, state, request, cache_key, request_id, shares, result_key, "
        "progress, current_value, points, created_ms, started_ms, finished_ms, cache_hit, "
        "client, lane, parent_id) VALUES ($1, $2, $3, $4, $5, NULLIF($6, ''), NULLIF($7, ''), "
        "$8, $9, CASE WHEN $10 THEN $11::float8 END, $12, $13, $14, $15, $16, $17, $18, $19)",
        id, request.kind, state, Bytes(request.request), request.cache_key, request.request_id,
        shares, result_key, progress, current_value.has_value(), current_value.value_or(0.0),
        points, now, started_ms, finished_ms, result.cache_hit, request.client, request.lane,
        request.parent);
    if (result.cache_hit) {
      tx.exec("UPDATE counters SET value = value + 1 WHERE name = 'cache_hits'");
    }
    result.id = id;
    return result;
  });
}

StatusOr<std::optional<JobRecord>> PostgresStoreImpl::ClaimNext(std::string_view worker_id,
                                                                const ClaimOptions& options) {
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  // Not under the store's write lock: claims of several workers proceed together, each locking
  // the row it takes (FOR UPDATE SKIP LOCKED passes over rows another claim holds). What the
  // other writers do to a queued job meanwhile is safe: Cancel takes a job claimed under it for
  // a running one (below, in Cancel), a follower inserted while its leader is claimed stays
  // QUEUED until the leader finishes, and the rest touch no queued job.
  return Claim<std::optional<JobRecord>>(
      "claim a job", [&](Tx& tx) -> StatusOr<std::optional<JobRecord>> {
        const int64_t lanes = LaneMask(options);
        std::string id;
        if (!options.parent.empty()) {
          // The parent runs its own tasks: only its children, oldest first.
          const pqxx::result r = tx.exec_params(
              "SELECT id FROM jobs WHERE parent_id = $1 AND parent_id <> '' AND state = 0 "
              "AND (($2::bigint >> lane) & 1) = 1 ORDER BY seq LIMIT 1 FOR UPDATE SKIP LOCKED",
              options.parent, lanes);
          if (r.empty()) return std::optional<JobRecord>();
          id = r[0][0].as<std::string>();
        } else {
          // Work already running first: the oldest QUEUED child of a RUNNING parent. The
          // locking read re-checks the child it locks (a cancel that committed meanwhile makes
          // it CANCELLED, and it is passed over); the parent's state is the snapshot's, but a
          // parent that left RUNNING since cancelled its queued children in the same commit.
          const pqxx::result r = tx.exec_params(
              "SELECT c.id FROM jobs c JOIN jobs p ON p.id = c.parent_id "
              "WHERE c.state = 0 AND c.parent_id <> '' AND p.state = 1 "
              "AND (($1::bigint >> c.lane) & 1) = 1 ORDER BY c.seq LIMIT 1 "
              "FOR UPDATE OF c SKIP LOCKED",
              lanes);
          if (!r.empty()) id = r[0][0].as<std::string>();
        }
        // Fair across clients: the clients with claimable jobs in the allowed lanes, by how many
        // jobs each has RUNNING in those lanes, then by the age of its oldest claimable job.
        const pqxx::result clients =
            id.empty()
                ? tx.exec_params(
                      "WITH heads AS ("
                      "  SELECT client, MIN(seq) AS seq FROM jobs"
                      "  WHERE state = 0 AND shares IS NULL AND parent_id = ''"
                      "  AND (($1::bigint >> lane) & 1) = 1"
                      "  GROUP BY client),"
                      " running AS ("
                      "  SELECT client, COUNT(*) AS n FROM jobs"
                      "  WHERE state = 1 AND shares IS NULL AND (($1::bigint >> lane) & 1) = 1"
                      "  GROUP BY client)"
                      " SELECT h.client FROM heads h LEFT JOIN running r ON r.client = h.client"
                      " ORDER BY COALESCE(r.n, 0), h.seq",
                      lanes)
                : pqxx::result();
        for (const pqxx::row& client : clients) {
          // The client's oldest claimable job that no other claim holds.
          const pqxx::result r = tx.exec_params(
              "SELECT id FROM jobs WHERE state = 0 AND shares IS NULL AND parent_id = '' "
              "AND client = $1 AND (($2::bigint >> lane) & 1) = 1 "
              "ORDER BY seq LIMIT 1 FOR UPDATE SKIP LOCKED",
              client[0].as<std::string>(), lanes);
          if (!r.empty()) {
            id = r[0][0].as<std::string>();
            break;
          }
        }
        if (id.empty()) return std::optional<JobRecord>();
        const int64_t now = NowMs();
        tx.exec_params(
            "UPDATE jobs SET state = 1, started_ms = $2, attempts = attempts + 1, run = run + 1, "
            "worker_id = $3, progress = 0, current_value = NULL, points = 0, "
            "lease_expires_ms = $4 WHERE id = $1 AND state = 0",
            id, now, StoredText(worker_id), ClaimedLeaseExpiry(now, options.lease_ms));
        // A new run starts from nothing (there is nothing to drop unless a bug left chunks).
        DRILLBIF_RETURN_IF_ERROR(DropRunChunks(tx, id));
        tx.exec_params("UPDATE jobs SET state = 1, started_ms = $2 WHERE shares = $1 AND state = 0",
                       id, now);
        const pqxx::result job = tx.exec_params(SelectJobs("request", "WHERE id = $1"), id);
        if (job.empty()) return Internal("claimed job '" + id + "' vanished");
        return std::optional<JobRecord>(ReadJob(job[0]));
      });
}

Status PostgresStoreImpl::UpdateProgress(std::string_view id, int64_t run, double fraction,
                                         std::optional<double> current_value, int64_t points) {
  DRILLBIF_RETURN_IF_ERROR(CheckProgress(fraction, current_value, points));
  return WriteStatus("update a job's progress", [&](Tx& tx) -> Status {
    DRILLBIF_RETURN_IF_ERROR(RunningHead(tx, id, "update progress of", run).status());
    tx.exec_params(
        "UPDATE jobs SET progress = $2, current_value = CASE WHEN $3 THEN $4::float8 END, "
        "points = $5 WHERE state = 1 AND ((id = $1 AND shares IS NULL) OR shares = $1)",
        std::string(id), fraction, current_value.has_value(), current_value.value_or(0.0), points);
    return Status::Ok();
  });
}

Status PostgresStoreImpl::Fail(std::string_view id, int64_t run, StatusCode code,
                               std::string_view message) {
  if (code == StatusCode::kOk) return InvalidArgument("a failed job needs an error code, not OK");
  return WriteStatus("fail a job", [&](Tx& tx) -> Status {
    DRILLBIF_RETURN_IF_ERROR(RunningHead(tx, id, "fail", run).status());
    return FailWithFollowers(tx, id, code, StoredText(message));
  });
}

StatusOr<JobState> PostgresStoreImpl::Cancel(std::string_view id) {
  return Write<JobState>("cancel a job", [&](Tx& tx) -> StatusOr<JobState> {
    DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(tx, id));
    const auto state = static_cast<JobState>(head.state);
    switch (state) {
      case JobState::kCancelled:
        return JobState::kCancelled;
      case JobState::kSucceeded:
      case JobState::kFailed:
        return AlreadyFinished(id, state);
      case JobState::kQueued:
      case JobState::kRunning:
        break;
    }
    if (state == JobState::kRunning && !head.shares) {
      // Its worker stops it: only the worker knows when the engine has let go.
      tx.exec_params("UPDATE jobs SET cancel_requested = TRUE WHERE id = $1 AND state = 1",
                     std::string(id));
      // Its tasks too: each task's worker sees the cancel on its own poll.
      DRILLBIF_RETURN_IF_ERROR(CancelChildren(tx, id));
      return JobState::kRunning;
    }
    // Nothing runs for it (queued, or following another job): cancelled at once. A queued job
    // that a claim (which does not take the write lock) took since Head read it is running
    // now: its worker is asked to stop instead.
    const pqxx::result cancelled = tx.exec_params(
        "UPDATE jobs SET state = 4, finished_ms = $2 WHERE id = $1 AND (state = 0 OR "
        "(state = 1 AND shares IS NOT NULL))",
        std::string(id), NowMs());
    if (cancelled.affected_rows() == 0) {
      tx.exec_params("UPDATE jobs SET cancel_requested = TRUE WHERE id = $1 AND state = 1",
                     std::string(id));
      return JobState::kRunning;
    }
    if (!head.shares) DRILLBIF_RETURN_IF_ERROR(PromoteFollower(tx, id));
    return JobState::kCancelled;
  });
}

StatusOr<bool> PostgresStoreImpl::IsCancelRequested(std::string_view id) {
  return ReadStatement<bool>("read a job", [&](Tx& tx) -> StatusOr<bool> {
    const pqxx::result r =
        tx.exec_params("SELECT cancel_requested FROM jobs WHERE id = $1", std::string(id));
    if (r.empty()) return NoJob(id);
    return r[0][0].as<bool>();
  });
}

Status PostgresStoreImpl::MarkCancelled(std::string_view id, int64_t run) {
  return WriteStatus("mark a job cancelled", [&](Tx& tx) -> Status {
    DRILLBIF_RETURN_IF_ERROR(RunningHead(tx, id, "mark cancelled", run).status());
    return CancelRunning(tx, id);
  });
}

Status PostgresStoreImpl::Requeue(std::string_view id, int64_t run) {
  return WriteStatus("requeue a job", [&](Tx& tx) -> Status {
    DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(tx, id, "requeue", run));
    // A cancel asked before the stop wins: the client does not want the job run again.
    if (head.cancel_requested) return CancelRunning(tx, id);
    return RequeueWithFollowers(tx, id, /*count_attempt=*/false);
  });
}

StatusOr<std::optional<std::string>> PostgresStoreImpl::FindSucceeded(std::string_view cache_key) {
  if (cache_key.empty()) return InvalidArgument("cache_key: must not be empty");
  using Found = std::optional<std::string>;
  return ReadStatement<Found>("find a result", [&](Tx& tx) -> StatusOr<Found> {
    const pqxx::result r = tx.exec_params(
        "SELECT id FROM jobs WHERE cache_key = $1 AND state = 2 ORDER BY seq LIMIT 1",
        std::string(cache_key));
    if (r.empty()) return Found();
    return Found(r[0][0].as<std::string>());
  });
}

StatusOr<JobRecord> PostgresStoreImpl::Get(std::string_view id, bool include_request) {
  return ReadStatement<JobRecord>("read a job", [&](Tx& tx) -> StatusOr<JobRecord> {
    const pqxx::result r =
        tx.exec_params(SelectJobs("CASE WHEN $2 THEN request ELSE ''::bytea END", "WHERE id = $1"),
                       std::string(id), include_request);
    if (r.empty()) return NoJob(id);
    return ReadJob(r[0]);
  });
}

StatusOr<ListResult> PostgresStoreImpl::List(const ListRequest& request) {
  if (request.page_size < 0) return InvalidArgument("page_size: must be >= 0");
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t after_seq, ParsePageToken(request.page_token));
  const int page_size =
      PageSize(request.page_size, options_.default_page_size, options_.max_page_size);
  return ReadStatement<ListResult>("list jobs", [&](Tx& tx) -> StatusOr<ListResult> {
    // Keyset pagination on seq: a page starts after the last seq seen, so jobs submitted or
    // deleted meanwhile never shift the pages (an offset would skip or repeat jobs).
    const pqxx::result r = tx.exec_params(
        SelectJobs("CASE WHEN $4 THEN request ELSE ''::bytea END",
                   "WHERE seq > $1 AND (NOT $2 OR state = $3) AND ($5 = '' OR kind = $5) "
                   "AND parent_id = $7 ORDER BY seq LIMIT $6"),
        after_seq, request.state.has_value(), request.state ? static_cast<int>(*request.state) : 0,
        request.include_request, request.kind, static_cast<int64_t>(page_size) + 1, request.parent);
    ListResult result;
    for (const pqxx::row& row : r) {
      if (static_cast<int>(result.jobs.size()) == page_size) {
        // One row more than the page: there is a next page.
        result.next_page_token = PageToken(r[page_size - 1][0].as<int64_t>());
        break;
      }
      result.jobs.push_back(ReadJob(row));
    }
    return result;
  });
}

StatusOr<RecoveryReport> PostgresStoreImpl::TakeBack(TakenBack why, int64_t now_ms) {
  return Write<RecoveryReport>(
      "take back interrupted jobs", [&](Tx& tx) -> StatusOr<RecoveryReport> {
        const pqxx::result r = tx.exec_params(
            "SELECT id FROM jobs WHERE state = 1 AND shares IS NULL "
            "AND ($1 OR (lease_expires_ms > 0 AND lease_expires_ms < $2)) ORDER BY seq",
            why == TakenBack::kRestart, now_ms);
        RecoveryReport report;
        for (const pqxx::row& job : r) {
          const std::string id = job[0].as<std::string>();
          // Read again: taking back a parent earlier in this loop asked its running children to
          // stop, and such a child must end CANCELLED, not be queued again without a parent.
          DRILLBIF_ASSIGN_OR_RETURN(const JobHead head, Head(tx, id));
          if (head.state != kRunning) continue;
          const int attempts = head.attempts;
          switch (TakeBackActionOf(head.cancel_requested, attempts, options_.max_attempts)) {
            case TakeBackAction::kCancel:
              DRILLBIF_RETURN_IF_ERROR(CancelRunning(tx, id));
              ++report.cancelled;
              break;
            case TakeBackAction::kFail:
              DRILLBIF_RETURN_IF_ERROR(
                  FailWithFollowers(tx, id, StatusCode::kInternal,
                                    TooManyAttempts(why, attempts, options_.max_attempts)));
              ++report.failed;
              break;
            case TakeBackAction::kRequeue:
              DRILLBIF_RETURN_IF_ERROR(RequeueWithFollowers(tx, id, /*count_attempt=*/true));
              ++report.requeued;
              break;
          }
        }
        return report;
      });
}

StatusOr<RecoveryReport> PostgresStoreImpl::RecoverAfterRestart() {
  return TakeBack(TakenBack::kRestart, 0);
}

StatusOr<RecoveryReport> PostgresStoreImpl::ReclaimExpiredLeases(int64_t now_ms) {
  return TakeBack(TakenBack::kLeaseExpired, now_ms);
}

Status PostgresStoreImpl::RenewLease(std::string_view id, int64_t run, int64_t lease_ms) {
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t expires, RenewedLeaseExpiry(lease_ms));
  return WriteStatus("renew a lease", [&](Tx& tx) -> Status {
    DRILLBIF_RETURN_IF_ERROR(RunningHead(tx, id, "renew the lease of", run).status());
    return UpdateRunning(tx, "UPDATE jobs SET lease_expires_ms = $2 WHERE id = $1 AND state = 1",
                         id, expires);
  });
}

StatusOr<StoreStats> PostgresStoreImpl::Stats() {
  return Read<StoreStats>("read the store's counters", [&](Tx& tx) -> StatusOr<StoreStats> {
    StoreStats stats;
    for (const pqxx::row& row : tx.exec("SELECT state, COUNT(*) FROM jobs GROUP BY state")) {
      const int state = row[0].as<int>();
      if (state >= 0 && state < kJobStateCount) stats.jobs_by_state[state] = row[1].as<int64_t>();
    }
    for (const pqxx::row& row : tx.exec("SELECT lane, COUNT(*) FROM jobs "
                                        "WHERE state = 0 AND shares IS NULL GROUP BY lane")) {
      const int lane = row[0].as<int>();
      const int64_t n = row[1].as<int64_t>();
      if (lane >= 0 && lane < kLaneCount) stats.queue_depth_by_lane[lane] = n;
      stats.queue_depth += n;
    }
    stats.cache_hits_total =
        tx.exec("SELECT value FROM counters WHERE name = 'cache_hits'")[0][0].as<int64_t>();
    DRILLBIF_ASSIGN_OR_RETURN(stats.used_bytes, UsedBytes(tx));
    return stats;
  });
}

StatusOr<std::unique_ptr<JobChangeFeed>> PostgresStoreImpl::OpenChangeFeed(
    JobChangeCallback on_change) {
  // The feed's log lines go where the store's go; they run on the feed's thread, without mu_.
  return OpenPostgresChangeFeed(WithPassword(uri_, options_.password), options_.log,
                                std::move(on_change));
}

Status PostgresJobStoreOptions::Validate() const {
  if (max_attempts < 1) return InvalidArgument("max_attempts: must be >= 1");
  if (idle_in_transaction_timeout_ms < 1) {
    return InvalidArgument("idle_in_transaction_timeout_ms: must be >= 1");
  }
  if (max_page_size < 1) return InvalidArgument("max_page_size: must be >= 1");
  if (default_page_size < 1 || default_page_size > max_page_size) {
    return InvalidArgument("default_page_size: must be in [1, max_page_size]");
  }
  return Status::Ok();
}

StatusOr<std::unique_ptr<JobStore>> PostgresJobStore::Open(const std::string& uri,
                                                           const PostgresJobStoreOptions& options) {
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  if (uri.empty()) return InvalidArgument("uri: must not be empty");
  auto store = std::make_unique<PostgresStoreImpl>(uri, options);
  DRILLBIF_RETURN_IF_ERROR(store->Configure());
  return std::unique_ptr<JobStore>(std::move(store));
}

}  // namespace drillbif::server
