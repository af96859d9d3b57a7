#include "jobs/request_bytes.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <openssl/evp.h>

#include "drillbif/version.h"

namespace drillbif::jobs {

std::string DeterministicBytes(const google::protobuf::Message& message) {
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    message.SerializeToCodedStream(&coded);
  }  // The coded stream flushes into `bytes` when it goes out of scope.
  return bytes;
}

std::string Sha256Hex(std::string_view data) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  EVP_Digest(data.data(), data.size(), digest, &length, EVP_sha256(), nullptr);
  std::string hex(2 * length, '0');
  static constexpr char kDigits[] = "0123456789abcdef";
  for (unsigned int i = 0; i < length; ++i) {
    hex[2 * i] = kDigits[digest[i] >> 4];
    hex[2 * i + 1] = kDigits[digest[i] & 15];
  }
  return hex;
}

std::string CacheKey(std::string_view kind_name, std::string_view request_bytes) {
  // Length prefixes make the concatenation unambiguous.
  std::string input;
  for (std::string_view part : {kind_name, std::string_view(EngineVersion()), request_bytes}) {
    input += std::to_string(part.size());
    input += ':';
    input += part;
  }
  return Sha256Hex(input);
}

}  // namespace drillbif::jobs
