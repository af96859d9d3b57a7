// Status: the result of an operation that can fail in an expected way (bad input, no convergence,
// a full disk). Codes map one-to-one onto gRPC status codes so that the service layer can pass
// them through. Both Status and StatusOr are [[nodiscard]]: an error that is dropped silently is a
// bug, so ignoring one takes an explicit `(void)` or `.IgnoreError()`.
//
//   Status Save(const Job& job) {
//     DRILLBIF_RETURN_IF_ERROR(Check(job));
//     DRILLBIF_ASSIGN_OR_RETURN(std::string bytes, Serialize(job));
//     return Write(bytes);
//   }
#ifndef DRILLBIF_COMMON_STATUS_H_
#define DRILLBIF_COMMON_STATUS_H_

#include <optional>
#include <string>
#include <utility>

namespace drillbif {

// Same numeric values as grpc::StatusCode / google.rpc.Code.
enum class StatusCode {
  kOk = 0,
  kCancelled = 1,
  kUnknown = 2,
  kInvalidArgument = 3,
  kDeadlineExceeded = 4,
  kNotFound = 5,
  kAlreadyExists = 6,
  kPermissionDenied = 7,
  kResourceExhausted = 8,
  kFailedPrecondition = 9,
  kAborted = 10,
  kOutOfRange = 11,
  kUnimplemented = 12,
  kInternal = 13,
  kUnavailable = 14,
  kDataLoss = 15,
  kUnauthenticated = 16,
};

// An OK status or an error code with a human-readable message. Cheap to copy when OK.
class [[nodiscard]] Status {
 public:
  Status() = default;
  Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

  static Status Ok() { return Status(); }

  bool ok() const { return code_ == StatusCode::kOk; }
  StatusCode code() const { return code_; }
  const std::string& message() const { return message_; }
  // "INVALID_ARGUMENT: xi must be > 0 (got -1)".
  std::string ToString() const;

  // Says that dropping this status is intended (a best-effort write whose failure is logged
  // elsewhere, a cleanup after an error that is already being reported).
  void IgnoreError() const {}

 private:
  StatusCode code_ = StatusCode::kOk;
  std::string message_;
};

inline Status InvalidArgument(std::string message) {
  return Status(StatusCode::kInvalidArgument, std::move(message));
}
inline Status OutOfRange(std::string message) {
  return Status(StatusCode::kOutOfRange, std::move(message));
}
inline Status Internal(std::string message) {
  return Status(StatusCode::kInternal, std::move(message));
}
inline Status NotFound(std::string message) {
  return Status(StatusCode::kNotFound, std::move(message));
}
inline Status FailedPrecondition(std::string message) {
  return Status(StatusCode::kFailedPrecondition, std::move(message));
}
inline Status ResourceExhausted(std::string message) {
  return Status(StatusCode::kResourceExhausted, std::move(message));
}
inline Status Unavailable(std::string message) {
  return Status(StatusCode::kUnavailable, std::move(message));
}
inline Status DeadlineExceeded(std::string message) {
  return Status(StatusCode::kDeadlineExceeded, std::move(message));
}
inline Status Cancelled(std::string message) {
  return Status(StatusCode::kCancelled, std::move(message));
}

// Name of a status code as in google.rpc.Code ("INVALID_ARGUMENT").
const char* StatusCodeName(StatusCode code);

namespace internal {
// Prints "StatusOr::value() on an error: <status>" to stderr and aborts: reading the value of an
// error is a programming error, never an expected failure.
[[noreturn]] void DieOnValueOfError(const Status& status);
}  // namespace internal

// A value or the Status that explains why there is none. value(), operator* and operator-> check
// that there is a value (and abort with the status otherwise).
template <typename T>
class [[nodiscard]] StatusOr {
 public:
  StatusOr(T value) : value_(std::move(value)) {}  // NOLINT: implicit by design
  // `status` must not be OK (an OK status without a value becomes INTERNAL).
  StatusOr(Status status) : status_(std::move(status)) {  // NOLINT: implicit by design
    if (status_.ok()) status_ = Internal("StatusOr constructed from an OK status without a value");
  }
  bool ok() const { return status_.ok(); }
  const Status& status() const& { return status_; }
  Status status() && { return std::move(status_); }
  const T& value() const& {
    Check();
    return *value_;
  }
  T& value() & {
    Check();
    return *value_;
  }
  T&& value() && {
    Check();
    return std::move(*value_);
  }
  const T& operator*() const& { return value(); }
  T& operator*() & { return value(); }
  T&& operator*() && { return std::move(*this).value(); }
  const T* operator->() const { return &value(); }
  T* operator->() { return &value(); }

 private:
  void Check() const {
    if (!value_) internal::DieOnValueOfError(status_);
  }

  Status status_;
  std::optional<T> value_;
};

}  // namespace drillbif

// Returns the Status of `expr` from the enclosing function unless it is OK. `expr` may be a Status
// or a StatusOr (its status is returned).
#define DRILLBIF_RETURN_IF_ERROR(expr)                                                \
  do {                                                                                \
    if (auto drillbif_status_ = ::drillbif::internal::StatusOf(expr);                \
        !drillbif_status_.ok()) {                                                     \
      return drillbif_status_;                                                        \
    }                                                                                 \
  } while (false)

// `lhs = value of expr` when `expr` (a StatusOr) holds a value; else returns its Status from the
// enclosing function. `lhs` may declare a variable: DRILLBIF_ASSIGN_OR_RETURN(auto x, F()). It is
// several statements: never the unbraced body of an if or a loop.
#define DRILLBIF_ASSIGN_OR_RETURN(lhs, expr) \
  DRILLBIF_ASSIGN_OR_RETURN_IMPL_(DRILLBIF_STATUS_CONCAT_(drillbif_statusor_, __LINE__), lhs, expr)

#define DRILLBIF_STATUS_CONCAT_INNER_(a, b) a##b
#define DRILLBIF_STATUS_CONCAT_(a, b) DRILLBIF_STATUS_CONCAT_INNER_(a, b)
#define DRILLBIF_ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
  auto tmp = (expr);                                    \
  if (!tmp.ok()) return std::move(tmp).status();        \
  lhs = std::move(tmp).value()

namespace drillbif::internal {
inline const Status& StatusOf(const Status& status) { return status; }
template <typename T>
const Status& StatusOf(const StatusOr<T>& status_or) {
  return status_or.status();
}
}  // namespace drillbif::internal

#endif  // DRILLBIF_COMMON_STATUS_H_
