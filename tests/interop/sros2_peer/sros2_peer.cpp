// sros2_peer: a DDS participant with DDS Security (SROS2 keystore layout) that carries
// ROS 2 topics as raw serialized CDR, for tests/test_security.py.
//
// Built against Debian's Fast DDS 2.9 (libfastrtps-dev), which has the builtin security
// plugins; the PyPI Fast DDS and Cyclone wheels the other tests use have none. No ROS 2
// type support is needed: one TopicDataType carries a sample's bytes as they are on the
// wire (the 4-byte encapsulation header included), under the ROS type name given.
//
//   sros2_peer [--enclave DIR] [--domain N] [--pub TOPIC TYPE]... [--sub TOPIC TYPE]...
//              [--latched TOPIC]... [--name NAME] [--verbose]
//
//   --enclave DIR   an SROS2 enclave directory (identity_ca.cert.pem, cert.pem, key.pem,
//                   permissions_ca.cert.pem, governance.p7s, permissions.p7s); without it
//                   the participant has no security
//   --pub/--sub     a DDS topic (rt/xyz_target) and type (geometry_msgs::msg::dds_::PointStamped_)
//   --latched TOPIC transient local, keep last 1 (else reliable, volatile, keep last 10);
//                   rt/estop, rt/robot_description and rt/tf_static are latched anyway
//
// stdin: one `TOPIC HEXPAYLOAD` line per sample to publish; EOF ends the program.
// stdout (one line each, flushed):
//   ready                                   the participant and endpoints exist
//   matched TOPIC pub|sub N                 N remote endpoints match ours now
//   recv TOPIC HEXPAYLOAD                   a sample received
//   participant discovered|changed|removed|dropped GUIDPREFIX NAME
//   auth ok|failed GUIDPREFIX               security handshake result
//   writer|reader TOPIC TYPE GUIDPREFIX     a remote endpoint discovered
//   published TOPIC                         a stdin line was written
// stderr: errors (and Fast DDS's own log: errors, or warnings with --verbose).
// Exit status: 0 at stdin EOF, 2 for bad arguments, 1 if the participant or an
// endpoint cannot be created (a bad keystore file, a topic the permissions deny).

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fastdds/dds/log/StdoutErrConsumer.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>

#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

using namespace eprosima::fastdds::dds;
using eprosima::fastrtps::rtps::SerializedPayload_t;
using eprosima::fastrtps::rtps::InstanceHandle_t;

namespace {

std::mutex out_mutex;

void say(const std::string& line)
{
    std::lock_guard<std::mutex> lock(out_mutex);
    std::fputs(line.c_str(), stdout);
    std::fputc('\n', stdout);
    std::fflush(stdout);
}

void complain(const std::string& line)
{
    std::lock_guard<std::mutex> lock(out_mutex);
    std::fprintf(stderr, "sros2_peer: %s\n", line.c_str());
    std::fflush(stderr);
}

std::string to_hex(const uint8_t* p, size_t n)
{
    static const char digits[] = "0123456789abcdef";
    std::string s(2 * n, '0');
    for (size_t i = 0; i < n; ++i) {
        s[2 * i] = digits[p[i] >> 4];
        s[2 * i + 1] = digits[p[i] & 15];
    }
    return s;
}

bool from_hex(const std::string& s, std::vector<uint8_t>& out)
{
    if (s.size() % 2) {
        return false;
    }
    out.clear();
    for (size_t i = 0; i < s.size(); i += 2) {
        unsigned v = 0;
        if (std::sscanf(s.c_str() + i, "%2x", &v) != 1 || !std::isxdigit(s[i]) || !std::isxdigit(s[i + 1])) {
            return false;
        }
        out.push_back(static_cast<uint8_t>(v));
    }
    return true;
}

std::string guid_prefix(const eprosima::fastrtps::rtps::GuidPrefix_t& prefix)
{
    return to_hex(prefix.value, sizeof(prefix.value));
}

// One sample: the serialized bytes, encapsulation header included.
struct RawSample {
    std::vector<uint8_t> bytes;
};

// A TopicDataType that moves bytes: whatever the type name, the sample is its CDR.
class RawType : public TopicDataType {
public:
    explicit RawType(const std::string& name)
    {
        setName(name.c_str());
        m_typeSize = 1024;  // a first guess: the payload pools grow (dynamic memory below)
        m_isGetKeyDefined = false;
    }

    bool serialize(void* data, SerializedPayload_t* payload) override
    {
        auto* s = static_cast<RawSample*>(data);
        if (s->bytes.size() < 4 || s->bytes.size() > payload->max_size) {
            return false;
        }
        std::memcpy(payload->data, s->bytes.data(), s->bytes.size());
        payload->length = static_cast<uint32_t>(s->bytes.size());
        payload->encapsulation = (s->bytes[1] & 1) ? CDR_LE : CDR_BE;
        return true;
    }

    bool deserialize(SerializedPayload_t* payload, void* data) override
    {
        auto* s = static_cast<RawSample*>(data);
        s->bytes.assign(payload->data, payload->data + payload->length);
        return true;
    }

    std::function<uint32_t()> getSerializedSizeProvider(void* data) override
    {
        auto* s = static_cast<RawSample*>(data);
        return [s]() { return static_cast<uint32_t>(s->bytes.size()); };
    }

    void* createData() override { return new RawSample(); }

    void deleteData(void* data) override { delete static_cast<RawSample*>(data); }

    bool getKey(void*, InstanceHandle_t*, bool) override { return false; }
};

class WriterListener : public DataWriterListener {
public:
    explicit WriterListener(std::string topic) : topic_(std::move(topic)) {}

    void on_publication_matched(DataWriter*, const PublicationMatchedStatus& status) override
    {
        say("matched " + topic_ + " pub " + std::to_string(status.current_count));
    }

private:
    std::string topic_;
};

class ReaderListener : public DataReaderListener {
public:
    explicit ReaderListener(std::string topic) : topic_(std::move(topic)) {}

    void on_subscription_matched(DataReader*, const SubscriptionMatchedStatus& status) override
    {
        say("matched " + topic_ + " sub " + std::to_string(status.current_count));
    }

    void on_data_available(DataReader* reader) override
    {
        RawSample sample;
        SampleInfo info;
        while (reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
            if (info.valid_data) {
                say("recv " + topic_ + " " + to_hex(sample.bytes.data(), sample.bytes.size()));
            }
        }
    }

private:
    std::string topic_;
};

class ParticipantListener : public DomainParticipantListener {
public:
    void on_participant_discovery(DomainParticipant*,
                                  eprosima::fastrtps::rtps::ParticipantDiscoveryInfo&& info) override
    {
        using I = eprosima::fastrtps::rtps::ParticipantDiscoveryInfo;
        const char* what = info.status == I::DISCOVERED_PARTICIPANT ? "discovered"
                           : info.status == I::CHANGED_QOS_PARTICIPANT ? "changed"
                           : info.status == I::REMOVED_PARTICIPANT ? "removed"
                                                                    : "dropped";
        say(std::string("participant ") + what + " " + guid_prefix(info.info.m_guid.guidPrefix) + " " +
            info.info.m_participantName.to_string());
    }

#if HAVE_SECURITY
    void onParticipantAuthentication(DomainParticipant*,
                                     eprosima::fastrtps::rtps::ParticipantAuthenticationInfo&& info) override
    {
        using I = eprosima::fastrtps::rtps::ParticipantAuthenticationInfo;
        say(std::string("auth ") + (info.status == I::AUTHORIZED_PARTICIPANT ? "ok " : "failed ") +
            guid_prefix(info.guid.guidPrefix));
    }
#endif

    // remote endpoints only (Fast DDS reports this participant's own endpoints here too)
    void on_subscriber_discovery(DomainParticipant* self, eprosima::fastrtps::rtps::ReaderDiscoveryInfo&& info) override
    {
        if (info.status == eprosima::fastrtps::rtps::ReaderDiscoveryInfo::DISCOVERED_READER &&
            info.info.guid().guidPrefix != self->guid().guidPrefix) {
            say("reader " + info.info.topicName().to_string() + " " + info.info.typeName().to_string() + " " +
                guid_prefix(info.info.guid().guidPrefix));
        }
    }

    void on_publisher_discovery(DomainParticipant* self, eprosima::fastrtps::rtps::WriterDiscoveryInfo&& info) override
    {
        if (info.status == eprosima::fastrtps::rtps::WriterDiscoveryInfo::DISCOVERED_WRITER &&
            info.info.guid().guidPrefix != self->guid().guidPrefix) {
            say("writer " + info.info.topicName().to_string() + " " + info.info.typeName().to_string() + " " +
                guid_prefix(info.info.guid().guidPrefix));
        }
    }
};

[[noreturn]] void usage(const std::string& why)
{
    std::fprintf(stderr,
                 "sros2_peer: %s\nusage: sros2_peer [--enclave DIR] [--domain N] [--pub TOPIC TYPE]... "
                 "[--sub TOPIC TYPE]... [--latched TOPIC]... [--name NAME] [--verbose]\n",
                 why.c_str());
    std::exit(2);
}

std::string file_uri(const std::string& dir, const char* file)
{
    return "file://" + dir + "/" + file;
}

}  // namespace

int main(int argc, char** argv)
{
    std::string enclave, name = "sros2_peer";
    int domain = 0;
    bool verbose = false;
    std::vector<std::pair<std::string, std::string>> pubs, subs;
    std::set<std::string> latched = {"rt/estop", "rt/robot_description", "rt/tf_static"};
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        auto need = [&](int n) {
            if (i + n >= argc) {
                usage(a + " needs " + std::to_string(n) + " value(s)");
            }
        };
        if (a == "--enclave") {
            need(1);
            enclave = argv[++i];
        } else if (a == "--domain") {
            need(1);
            char* end = nullptr;
            long d = std::strtol(argv[++i], &end, 10);
            if (*end || d < 0 || d > 232) {
                usage(std::string("bad domain ") + argv[i]);
            }
            domain = static_cast<int>(d);
        } else if (a == "--pub" || a == "--sub") {
            need(2);
            (a == "--pub" ? pubs : subs).emplace_back(argv[i + 1], argv[i + 2]);
            i += 2;
        } else if (a == "--latched") {
            need(1);
            latched.insert(argv[++i]);
        } else if (a == "--name") {
            need(1);
            name = argv[++i];
        } else if (a == "--verbose") {
            verbose = true;
        } else {
            usage("unknown argument " + a);
        }
    }
    if (!enclave.empty() && enclave.back() == '/') {
        enclave.pop_back();
    }

    // Fast DDS's log on stderr only: stdout is this program's protocol.
    Log::ClearConsumers();
    auto consumer = std::make_unique<StdoutErrConsumer>();
    consumer->stderr_threshold(Log::Kind::Info);
    Log::RegisterConsumer(std::move(consumer));
    Log::SetVerbosity(verbose ? Log::Kind::Warning : Log::Kind::Error);

    DomainParticipantQos pqos;
    pqos.name(name);
    // UDP only: shared memory would bypass the network a test captures on
    pqos.transport().use_builtin_transports = false;
    pqos.transport().user_transports.push_back(
        std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>());
    if (!enclave.empty()) {
        auto& p = pqos.properties().properties();
        p.emplace_back("dds.sec.auth.plugin", "builtin.PKI-DH");
        p.emplace_back("dds.sec.auth.builtin.PKI-DH.identity_ca", file_uri(enclave, "identity_ca.cert.pem"));
        p.emplace_back("dds.sec.auth.builtin.PKI-DH.identity_certificate", file_uri(enclave, "cert.pem"));
        p.emplace_back("dds.sec.auth.builtin.PKI-DH.private_key", file_uri(enclave, "key.pem"));
        p.emplace_back("dds.sec.access.plugin", "builtin.Access-Permissions");
        p.emplace_back("dds.sec.access.builtin.Access-Permissions.permissions_ca",
                       file_uri(enclave, "permissions_ca.cert.pem"));
        p.emplace_back("dds.sec.access.builtin.Access-Permissions.governance", file_uri(enclave, "governance.p7s"));
        p.emplace_back("dds.sec.access.builtin.Access-Permissions.permissions", file_uri(enclave, "permissions.p7s"));
        p.emplace_back("dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC");
    }

    ParticipantListener participant_listener;
    StatusMask mask = StatusMask::none();  // endpoint statuses go to the endpoints' listeners
    DomainParticipant* participant =
        DomainParticipantFactory::get_instance()->create_participant(domain, pqos, &participant_listener, mask);
    if (participant == nullptr) {
        complain("cannot create the participant" +
                 (enclave.empty() ? std::string() : " with the enclave " + enclave) +
                 " (Fast DDS's log above says why)");
        Log::Flush();
        return 1;
    }
    Publisher* publisher = participant->create_publisher(PUBLISHER_QOS_DEFAULT);
    Subscriber* subscriber = participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);

    std::map<std::string, Topic*> topics;
    auto topic_of = [&](const std::string& topic, const std::string& type) -> Topic* {
        auto it = topics.find(topic);
        if (it != topics.end()) {
            return it->second;
        }
        if (participant->find_type(type).empty()) {
            TypeSupport ts(new RawType(type));
            ts.register_type(participant);
        }
        Topic* t = participant->create_topic(topic, type, TOPIC_QOS_DEFAULT);
        topics[topic] = t;
        return t;
    };
    auto history = [&](const std::string& topic, auto& qos) {
        qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
        if (latched.count(topic)) {
            qos.durability().kind = TRANSIENT_LOCAL_DURABILITY_QOS;
            qos.history().kind = KEEP_LAST_HISTORY_QOS;
            qos.history().depth = 1;
        } else {
            qos.durability().kind = VOLATILE_DURABILITY_QOS;
            qos.history().kind = KEEP_LAST_HISTORY_QOS;
            qos.history().depth = 10;
        }
        qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::DYNAMIC_RESERVE_MEMORY_MODE;
        qos.data_sharing().off();
    };

    int failed = 0;
    std::vector<std::unique_ptr<WriterListener>> writer_listeners;
    std::vector<std::unique_ptr<ReaderListener>> reader_listeners;
    std::map<std::string, DataWriter*> writers;
    std::vector<DataReader*> readers;
    // A writer or reader (`what`) of `topic` with the topic's QoS and a listener of its
    // own kept in `listeners`, made by `create`; nullptr, complained about and counted
    // in `failed`, when it cannot be made.
    auto endpoint = [&](const std::string& topic, const std::string& type, const char* what, auto qos,
                        auto& listeners, auto create) {
        Topic* t = topic_of(topic, type);
        history(topic, qos);
        using Listener = typename std::decay_t<decltype(listeners)>::value_type::element_type;
        listeners.push_back(std::make_unique<Listener>(topic));
        auto* made = t ? create(t, qos, listeners.back().get()) : nullptr;
        if (made == nullptr) {
            complain(std::string("cannot create a ") + what + " of " + topic + " (" + type +
                     "): denied by the permissions?");
            ++failed;
        }
        return made;
    };
    for (auto& [topic, type] : pubs) {
        DataWriter* w = endpoint(topic, type, "writer", DATAWRITER_QOS_DEFAULT, writer_listeners,
                                 [&](Topic* t, const DataWriterQos& qos, WriterListener* l) {
                                     return publisher->create_datawriter(t, qos, l);
                                 });
        if (w != nullptr) {
            writers[topic] = w;
        }
    }
    for (auto& [topic, type] : subs) {
        DataReader* r = endpoint(topic, type, "reader", DATAREADER_QOS_DEFAULT, reader_listeners,
                                 [&](Topic* t, const DataReaderQos& qos, ReaderListener* l) {
                                     return subscriber->create_datareader(t, qos, l);
                                 });
        if (r != nullptr) {
            readers.push_back(r);
        }
    }
    if (failed) {
        Log::Flush();
        participant->delete_contained_entities();
        DomainParticipantFactory::get_instance()->delete_participant(participant);
        return 1;
    }
    say("ready");

    std::string line;
    while (std::getline(std::cin, line)) {
        if (line.empty() || line[0] == '#') {
            continue;
        }
        std::istringstream in(line);
        std::string topic, hex;
        in >> topic >> hex;
        auto it = writers.find(topic);
        RawSample sample;
        if (it == writers.end()) {
            complain("not a --pub topic: " + topic);
        } else if (!from_hex(hex, sample.bytes) || sample.bytes.size() < 4) {
            complain("not a hex CDR payload (with its 4-byte header): " + line);
        } else if (!it->second->write(&sample)) {
            complain("write failed on " + topic);
        } else {
            say("published " + topic);
        }
    }

    Log::Flush();
    participant->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(participant);
    return 0;
}
