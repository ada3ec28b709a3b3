// ros_peer: an independent ROS 2 wire peer on eProsima Fast DDS 2.x (Debian 12: libfastrtps-dev 2.9.1,
// libfastcdr-dev 1.0.26), which the tests use to show that anodize's DDS topics are ROS 2 topics.
//
// The message types are hand-written TopicDataType subclasses serialising with Fast CDR, not code from
// fastddsgen: on Debian 12 fastddsgen 2.3 needs a Java runtime (openjdk-17-jre-headless: 44 MB to
// download, 189 MB installed) and 32 more packages (ANTLR, Maven plugins, ...: 37 MB), and it generates
// ~1400 lines for Twist alone, while each ROS layout here takes a few lines. The build is one g++ call
// of about 2 s. Hand-written types also register no XTypes TypeObject / TypeInformation, so peers match
// them by type name alone (publish-bad-joy relies on that).
//
// Wire conventions of ROS 2: topic "rt/<name>", type "pkg::msg::dds_::Name_", plain little-endian CDR
// (encapsulation 00 01 00 00) and the default QoS RELIABLE, VOLATILE, KEEP_LAST 10.
//
// Build: g++ -std=c++17 -O1 main.cpp -o ros_peer -lfastrtps -lfastcdr   (tests/anodize/ros_peer.py does)
//
// Subcommands (exit 0 on success, 2 when a listener times out, 3 when a publisher finds no reader, 64 on
// bad usage); each also takes --rcvbuf BYTES, the participant's UDP receive buffer (default: the OS's):
//   listen-twist    --topic T --domain D --count N --timeout S
//   listen-image    --topic T --domain D --count N --timeout S
//   publish-joy     --topic T --domain D --count N --period-ms P --wait-match S [--typehash RIHS01_...]
//   publish-bad-joy --topic T --domain D --count N --period-ms P --wait-match S

#include <fastcdr/Cdr.h>
#include <fastcdr/FastBuffer.h>
#include <fastcdr/exceptions/Exception.h>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <thread>
#include <vector>

using namespace eprosima::fastdds::dds;
using eprosima::fastcdr::Cdr;
using eprosima::fastrtps::rtps::SerializedPayload_t;
using eprosima::fastrtps::rtps::InstanceHandle_t;
using Clock = std::chrono::steady_clock;

// ---- The ROS 2 (Jazzy) message layouts ------------------------------------------------------------

struct Time {  // builtin_interfaces/Time
    int32_t sec = 0;
    uint32_t nanosec = 0;
    void serialize(Cdr& c) const { c << sec << nanosec; }
    void deserialize(Cdr& c) { c >> sec >> nanosec; }
};

struct Header {  // std_msgs/Header
    Time stamp;
    std::string frame_id;
    void serialize(Cdr& c) const { c << stamp << frame_id; }
    void deserialize(Cdr& c) { c >> stamp >> frame_id; }
    size_t bound() const { return 16 + frame_id.size(); }
};

struct Vector3 {  // geometry_msgs/Vector3
    double x = 0, y = 0, z = 0;
    void serialize(Cdr& c) const { c << x << y << z; }
    void deserialize(Cdr& c) { c >> x >> y >> z; }
};

struct Twist {  // geometry_msgs/Twist
    static constexpr const char* name = "geometry_msgs::msg::dds_::Twist_";
    Vector3 linear, angular;
    void serialize(Cdr& c) const { c << linear << angular; }
    void deserialize(Cdr& c) { c >> linear >> angular; }
    size_t bound() const { return 56; }
};

struct Joy {  // sensor_msgs/Joy
    static constexpr const char* name = "sensor_msgs::msg::dds_::Joy_";
    Header header;
    std::vector<float> axes;
    std::vector<int32_t> buttons;
    void serialize(Cdr& c) const { c << header << axes << buttons; }
    void deserialize(Cdr& c) { c >> header >> axes >> buttons; }
    size_t bound() const { return header.bound() + 16 + 4 * (axes.size() + buttons.size()); }
};

struct BadJoy {  // what a node built against another definition of sensor_msgs/Joy would send
    static constexpr const char* name = "sensor_msgs::msg::dds_::Joy_";
    uint8_t junk[3] = {0, 0, 0};
    void serialize(Cdr& c) const { c.serializeArray(junk, 3); }
    void deserialize(Cdr& c) { c.deserializeArray(junk, 3); }
    size_t bound() const { return 8; }
};

struct Image {  // sensor_msgs/Image
    static constexpr const char* name = "sensor_msgs::msg::dds_::Image_";
    Header header;
    uint32_t height = 0, width = 0;
    std::string encoding;
    uint8_t is_bigendian = 0;
    uint32_t step = 0;
    std::vector<uint8_t> data;
    void serialize(Cdr& c) const { c << header << height << width << encoding << is_bigendian << step << data; }
    void deserialize(Cdr& c) { c >> header >> height >> width >> encoding >> is_bigendian >> step >> data; }
    size_t bound() const { return header.bound() + 32 + encoding.size() + data.size(); }
};

// One DDS type per message: XCDR1 little endian, keyless, no TypeObject.
template <class T>
class RosType : public TopicDataType {
public:
    RosType() {
        setName(T::name);
        m_typeSize = 4 + 4096;  // a first payload size; history memory is reallocated for larger samples
        m_isGetKeyDefined = false;
        auto_fill_type_object(false);
        auto_fill_type_information(false);
    }
    bool serialize(void* data, SerializedPayload_t* payload) override {
        eprosima::fastcdr::FastBuffer buffer(reinterpret_cast<char*>(payload->data), payload->max_size);
        Cdr cdr(buffer, Cdr::LITTLE_ENDIANNESS, Cdr::DDS_CDR);
        payload->encapsulation = CDR_LE;
        try {
            cdr.serialize_encapsulation();
            static_cast<const T*>(data)->serialize(cdr);
        } catch (eprosima::fastcdr::exception::Exception&) {
            return false;
        }
        payload->length = static_cast<uint32_t>(cdr.getSerializedDataLength());
        return true;
    }
    bool deserialize(SerializedPayload_t* payload, void* data) override {
        eprosima::fastcdr::FastBuffer buffer(reinterpret_cast<char*>(payload->data), payload->length);
        Cdr cdr(buffer, Cdr::DEFAULT_ENDIAN, Cdr::DDS_CDR);
        try {
            cdr.read_encapsulation();
            static_cast<T*>(data)->deserialize(cdr);
        } catch (eprosima::fastcdr::exception::Exception&) {
            return false;  // not a sample of this layout
        }
        return true;
    }
    std::function<uint32_t()> getSerializedSizeProvider(void* data) override {
        return [data] { return static_cast<uint32_t>(4 + static_cast<T*>(data)->bound()); };
    }
    void* createData() override { return new T(); }
    void deleteData(void* data) override { delete static_cast<T*>(data); }
    bool getKey(void*, InstanceHandle_t*, bool) override { return false; }
};

// ---- Command line ---------------------------------------------------------------------------------

struct Options {
    std::map<std::string, std::string> values;
    std::string get(const std::string& key, const std::string& fallback = "") const {
        auto it = values.find(key);
        return it == values.end() ? fallback : it->second;
    }
    long number(const std::string& key, long fallback) const {
        std::string text = get(key);
        return text.empty() ? fallback : std::strtol(text.c_str(), nullptr, 10);
    }
};

// ---- DDS plumbing -----------------------------------------------------------------------------------

template <class E>
E* must(E* entity, const char* what) {  // an entity Fast DDS created, or the end of the program
    if (entity == nullptr) {
        std::fprintf(stderr, "ros_peer: cannot create the %s\n", what);
        std::exit(1);
    }
    return entity;
}

template <class T>
struct Node {  // a participant with one topic of type T
    DomainParticipant* participant = nullptr;
    Topic* topic = nullptr;
    explicit Node(const Options& options) {
        auto domain = static_cast<DomainId_t>(options.number("domain", 0));
        DomainParticipantQos qos = PARTICIPANT_QOS_DEFAULT;
        // --rcvbuf: the UDP receive buffer; 0, the default, leaves the OS default, as rmw_fastrtps does.
        qos.transport().listen_socket_buffer_size = static_cast<uint32_t>(options.number("rcvbuf", 0));
        participant = must(DomainParticipantFactory::get_instance()->create_participant(domain, qos), "participant");
        TypeSupport type(new RosType<T>());
        type.register_type(participant);
        topic = must(participant->create_topic(options.get("topic"), type.get_type_name(), TOPIC_QOS_DEFAULT), "topic");
    }
    Node(const Node&) = delete;
    Node& operator=(const Node&) = delete;
    ~Node() {
        participant->delete_contained_entities();
        DomainParticipantFactory::get_instance()->delete_participant(participant);
    }
};

template <class Q>
void ros_default_qos(Q& qos) {  // rmw_qos_profile_default
    qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    qos.durability().kind = VOLATILE_DURABILITY_QOS;
    qos.history().kind = KEEP_LAST_HISTORY_QOS;
    qos.history().depth = 10;
    qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::DYNAMIC_REUSABLE_MEMORY_MODE;
}

// Takes up to --count samples (waiting at most --timeout seconds in all) and hands each to `seen`.
template <class T, class Seen>
long listen(const Options& options, Seen seen) {
    Node<T> node(options);
    DataReaderQos qos = DATAREADER_QOS_DEFAULT;
    ros_default_qos(qos);
    Subscriber* subscriber = must(node.participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT), "subscriber");
    DataReader* reader = must(subscriber->create_datareader(node.topic, qos), "reader");
    long count = options.number("count", 1), got = 0;
    auto deadline = Clock::now() + std::chrono::milliseconds(1000 * options.number("timeout", 10));
    T sample;
    SampleInfo info;
    while (got < count && Clock::now() < deadline) {
        reader->wait_for_unread_message(eprosima::fastrtps::Duration_t(0, 100000000));
        while (got < count && reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
            if (info.valid_data) {
                seen(sample);
                got++;
            }
        }
    }
    return got;
}

template <class T, class Make>
int publish(const Options& options, Make make) {
    Node<T> node(options);
    DataWriterQos qos = DATAWRITER_QOS_DEFAULT;
    ros_default_qos(qos);
    // Heartbeats every 100 ms, not every 3 s: Cyclone readers acknowledged only after a periodic heartbeat
    // (in tests: not within 2 s otherwise), and the acknowledgements end the program below.
    qos.reliable_writer_qos().times.heartbeatPeriod = eprosima::fastrtps::Duration_t(0, 100000000);
    std::string typehash = options.get("typehash");
    if (!typehash.empty()) {  // as rmw of ROS 2 Iron and later
        std::string text = "typehash=" + typehash + ";";
        qos.user_data().setValue(std::vector<eprosima::fastrtps::rtps::octet>(text.begin(), text.end()));
    }
    Publisher* publisher = must(node.participant->create_publisher(PUBLISHER_QOS_DEFAULT), "publisher");
    DataWriter* writer = must(publisher->create_datawriter(node.topic, qos), "writer");
    auto deadline = Clock::now() + std::chrono::milliseconds(1000 * options.number("wait-match", 10));
    PublicationMatchedStatus status;
    while (writer->get_publication_matched_status(status) == ReturnCode_t::RETCODE_OK && status.current_count == 0) {
        if (Clock::now() > deadline) {
            std::fprintf(stderr, "ros_peer: no reader matched %s within the wait\n", options.get("topic").c_str());
            return 3;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    // The reader may learn of this writer a little after we learnt of it; a volatile reader would miss
    // what comes before.
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    long count = options.number("count", 1);
    for (long i = 0; i < count; i++) {
        T sample = make(i);
        if (!writer->write(&sample)) {
            std::fprintf(stderr, "ros_peer: write %ld failed\n", i);
            return 1;
        }
        std::printf("{\"published\": %ld}\n", i);
        std::fflush(stdout);
        std::this_thread::sleep_for(std::chrono::milliseconds(options.number("period-ms", 100)));
    }
    // Keep the writer until every reader has acknowledged every sample (at most 2 s): reliable delivery
    // is then complete.
    auto start = Clock::now();
    bool acknowledged = writer->wait_for_acknowledgments({2, 0}) == ReturnCode_t::RETCODE_OK;
    std::fprintf(stderr, "ros_peer: %s after %.3f s\n", acknowledged ? "all acknowledged" : "not all acknowledged",
                 std::chrono::duration<double>(Clock::now() - start).count());
    return 0;
}

// ---- Subcommands ------------------------------------------------------------------------------------

int listen_twist(const Options& options) {
    auto seen = [](const Twist& t) {
        std::printf("{\"linear\": [%.17g, %.17g, %.17g], \"angular\": [%.17g, %.17g, %.17g]}\n", t.linear.x,
                    t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z);
        std::fflush(stdout);
    };
    return listen<Twist>(options, seen) == options.number("count", 1) ? 0 : 2;
}

int listen_image(const Options& options) {
    Clock::time_point first, last;
    long images = 0;
    auto seen = [&](const Image& image) {
        last = Clock::now();
        if (images++ == 0) first = last;
        uint32_t sum = 0;
        for (uint8_t byte : image.data) sum += byte;
        std::printf("{\"width\": %u, \"height\": %u, \"encoding\": \"%s\", \"bytes\": %zu, \"sum\": %u}\n",
                    image.width, image.height, image.encoding.c_str(), image.data.size(), sum);
        std::fflush(stdout);
    };
    long got = listen<Image>(options, seen);
    double seconds = images > 0 ? std::chrono::duration<double>(last - first).count() : 0.0;
    std::printf("{\"images\": %ld, \"seconds\": %.6f, \"per_second\": %.3f}\n", got, seconds,
                seconds > 0 ? (images - 1) / seconds : 0.0);
    std::fflush(stdout);
    return got == options.number("count", 1) ? 0 : 2;
}

int publish_joy(const Options& options) {
    return publish<Joy>(options, [](long i) {
        Joy joy;
        joy.header.stamp.sec = static_cast<int32_t>(i);
        joy.header.frame_id = "joy";
        joy.axes = {static_cast<float>(0.1 * static_cast<double>(i)), -0.5f, 1.0f};
        joy.buttons = {static_cast<int32_t>(i % 2), 1, 0};
        return joy;
    });
}

int publish_bad_joy(const Options& options) {
    return publish<BadJoy>(options, [](long i) {
        BadJoy joy;
        joy.junk[0] = 0xAB;
        joy.junk[1] = 0xCD;
        joy.junk[2] = static_cast<uint8_t>(i);
        return joy;
    });
}

int main(int argc, char** argv) {
    const std::map<std::string, int (*)(const Options&)> commands = {
        {"listen-twist", listen_twist},
        {"listen-image", listen_image},
        {"publish-joy", publish_joy},
        {"publish-bad-joy", publish_bad_joy},
    };
    auto command = argc > 1 ? commands.find(argv[1]) : commands.end();
    Options options;
    bool usage = command == commands.end() || argc % 2 != 0;
    for (int i = 2; !usage && i + 1 < argc; i += 2) {
        std::string key = argv[i];
        usage = key.rfind("--", 0) != 0;
        options.values[key.substr(2)] = argv[i + 1];
    }
    if (usage) {
        std::fprintf(stderr, "usage: ros_peer {listen-twist|listen-image|publish-joy|publish-bad-joy} "
                             "--topic rt/NAME --domain D --count N [--timeout S | --period-ms P --wait-match S "
                             "[--typehash RIHS01_...]] [--rcvbuf BYTES]\n");
        return 64;
    }
    std::setvbuf(stdout, nullptr, _IOLBF, 0);
    return command->second(options);
}
