// Every proto of proto/ (and the well-known types they import) as a serialized
// google.protobuf.FileDescriptorSet made by protoc with --include_imports --include_source_info,
// so that the proto comments are available at run time (SourceCodeInfo): the generated code of
// drillbif_proto keeps no comments. Built by proto/CMakeLists.txt
// (drillbif_proto_descriptor_set); files appear in dependency order, as DescriptorPool::BuildFile
// needs them.
#ifndef DRILLBIF_PROTO_DESCRIPTOR_SET_H_
#define DRILLBIF_PROTO_DESCRIPTOR_SET_H_

#include <string_view>

namespace drillbif::proto {

// The serialized FileDescriptorSet (static storage: valid for the program's life).
std::string_view DescriptorSet();

}  // namespace drillbif::proto

#endif  // DRILLBIF_PROTO_DESCRIPTOR_SET_H_
