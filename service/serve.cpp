#include "isotouch/service/serve.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <deque>
#include <filesystem>
#include <future>
#include <set>
#include <iomanip>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <ostream>
#include <sstream>
#include <thread>
#include <unistd.h>
#include <vector>

#include <igtlStatusMessage.h>

#include "isotouch/session/edit_session.h"
#include "isotouch/io/journal_offer.h"
#include "isotouch/io/vdb_io.h"
#include "isotouch/io/volume_io.h"
#include "isotouch/service/commands.h"
#include "isotouch/service/tool_ticks.h"
#include "isotouch/service/device_echo.h"
#include "isotouch/service/edit_mirror.h"
#include "isotouch/core/exit_codes.h"
#include "isotouch/service/igtl_device.h"
#include "isotouch/servo/hri.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/image_volume.h"
#include "isotouch/service/image_isovalue.h"
#include "isotouch/service/label_map.h"
#include "isotouch/service/outbox.h"
#include "isotouch/session/live_session.h"
#include "isotouch/session/session.h"
#include "isotouch/run/haptic_device.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/session/stop_signal.h"
#include "isotouch/service/stream_replies.h"
#include "isotouch/service/transform_device.h"
#include "isotouch/sim/stability.h"
#include "isotouch/servo/triple_buffer.h"
#include "isotouch/servo/cpu_placement.h"

namespace isotouch::service {
namespace {

/// Lines from several threads, whole.
class Log {
 public:
  explicit Log(std::ostream& out) : out_(out) {}
  void line(const std::string& s) {
    std::lock_guard<std::mutex> lock(mu_);
    out_ << s << "\n" << std::flush;
  }

 private:
  std::ostream& out_;
  std::mutex mu_;
};

struct Counters {
  std::atomic<long> clients{0}, images{0}, refused{0}, transforms{0}, strings{0}, skipped{0}, broken{0};
  std::atomic<long> sent{0}, dropped_sends{0}, busy_sends{0}, commands{0}, images_sent{0};
  std::atomic<long> idle{0}, dropped_clients{0};
  std::atomic<long> label_maps{0};  // label map IMAGEs taken as the session's materials
};

/// The most bytes that may wait in a client's Outbox behind the message being sent; past it
/// the client is not reading and is dropped.
constexpr std::size_t kOutboxBytes = std::size_t(64) << 20;

struct Client {
  std::shared_ptr<Connection> conn;
  std::shared_ptr<Outbox> outbox;  // the STATUS answers and edited IMAGEs, sent by its own thread
  std::thread thread;
  std::atomic<bool> done{false};
  /// Sent an IMAGE or a command: gets the edited volume back.
  std::atomic<bool> subscribed{false};
  /// Was the stream's client (--reply-force) at some time: gets its forces from the reply
  /// thread alone, never the display loop's Force copy (PLUS applies every Force it gets).
  std::atomic<bool> reply_target{false};
  /// Closed to give its slot to a new connection (the accept thread's, under clients_mu_): its
  /// slot counts as free while its thread ends.
  bool evicted = false;
  int id = 0;
  /// Its stream's rate check (Server::check_stream_rate; this client's thread only): the
  /// times between its latest poses [ns] (a ring), how many gaps so far, whether a stiffness
  /// over the bound was allowed (said once) or refused.
  std::array<std::int64_t, 15> stream_gaps_ns{};
  std::size_t stream_gap_count = 0, stream_over = 0;  // gaps seen; judgements over the bound in a row
  std::int64_t stream_last_ns = 0;
  bool stream_warned = false, stream_refused = false;
  /// The link's stiffness bounds it was judged by, by the rate simulated (its rate's bucket,
  /// Server::check_stream_rate): each simulated once (20-30 ms), in a thread of its own
  /// (stream_bound_next, for the rate stream_bound_next_hz), one at a time.
  std::map<double, LinkStiffness> stream_bounds;
  std::future<LinkStiffness> stream_bound_next;
  double stream_bound_next_hz = 0;
};

/// A command on its way to the command thread, and whom to answer.
struct Pending {
  Command cmd;
  std::shared_ptr<Outbox> from;
  std::string device;  // the STRING's device name, the STATUS's
  int client = 0;
};

/// A received label map's materials waiting for the main thread, for the session of
/// `generation` (the one its grid was checked against).
struct PendingLabels {
  std::shared_ptr<const materials::LabelVolume> labels;
  std::shared_ptr<Outbox> from;
  std::string device;
  std::uint64_t generation = 0;
  int client = 0;
};

/// A received IMAGE's volume waiting for the main thread, and whom to answer once it is
/// the session's (or could not be made so).
struct PendingVolume {
  engine::Volume volume;
  std::shared_ptr<Outbox> from;
  std::string device;  // the IMAGE's device name, the STATUS's
  std::string dims;    // "X x Y x Z"
  int client = 0;
};

/// One session on one volume: the edits, the buffer the servo reads, the renderer, the
/// live session around them.
struct Session {
  std::shared_ptr<EditMirror> mirror;  // before parts: the live session's listener writes it
  /// The edit session, its snapshots, the renderer and (once started) the live session.
  std::unique_ptr<session::Session> parts;
  session::LiveSession& live() { return *parts->live(); }
  engine::Volume frame;  // the volume's grid, direction and value range (voxels dropped)
  session::BrushTargets targets;  // the tool's material and empty values at this isovalue
  std::string image_name;  // the device name the edited volume goes back under
  std::uint64_t generation = 0;  // a new one per start_session
  /// A client's label map (its LBMETA's materials) the drill cuts by; null: none (the scene's
  /// own materials, if any, for the scene's volume).
  std::shared_ptr<const materials::LabelVolume> labels;
  io::Journal* journal = nullptr;  // where its edits go (the scene's volume's session, an IMAGE's): Server-owned
};

class Server {
 public:
  Server(const io::Scene& scene, const ServeOptions& o, std::ostream& out)
      : scene_(scene), o_(o), log_(out), listener_(o.host, o.port) {
    o_.limits.admit_image = [this](const std::string& device, const ImageSize& size) { return admit_image(device, size); };
    if (!o.haptic.empty() && o.reply_force)
      throw std::invalid_argument("--reply-force answers the TRANSFORM stream's poses; with --haptic " + o.haptic +
                                  " the stream is not the device");
    if (!o.haptic.empty() && !o.registration.is_identity())
      throw std::invalid_argument("--registration maps the TRANSFORM stream's poses; with --haptic " + o.haptic +
                                  " the stream is not the device");
  }

  int run();

 private:
  void client_loop(Client& c);
  void read_messages(Client& c);
  bool evict_quietest();
  void refuse_connection(int fd);
  void handle(Client& c, Incoming& in);
  void refuse(Client& c, const Incoming& in, int code, const std::string& why);
  bool own_stream(Client& c, const Incoming& in);
  bool check_stream_rate(Client& c, const Incoming& in);
  void leave_stream_zero(Client& c, const std::string& before);
  void take_registration(Client& c, const Incoming& in);
  void release_stream(int client);
  void display_loop();
  void display_tick(double stall_s);
  std::unique_ptr<Session> prepare_session(engine::Volume v, const session::LiveFieldOptions& live,
                                           const servo::HriParams& hri);
  void start_session(std::unique_ptr<Session> s);
  io::OpenedJournal find_journal(std::uint32_t volume_crc32);
  void start_journal(Session& s, io::OpenedJournal& j, std::uint32_t volume_crc32, const std::string& input,
                     const core::Isosurface& iso);
  io::OpenedJournal open_journal(Session& s, std::uint32_t volume_crc32, const std::string& input,
                                 const core::Isosurface& iso);
  void set_journal_aside(std::unique_ptr<io::Journal>& journal, const std::string& why);
  io::OpenedJournal carry_journal(io::OpenedJournal& from, Session& s, const std::optional<core::Isosurface>& iso,
                                  const std::vector<std::size_t>& restarts);
  void close_journal();
  std::string memory_refusal(const std::string& device, const ImageSize& size, std::uint64_t own_held_bytes);
  std::string memory_refusal(igtl::ImageMessage& image, std::uint64_t own_held_bytes);
  AdmittedImage admit_image(const std::string& device, const ImageSize& size);
  std::uint64_t session_bytes_per_voxel() const;
  void swap_volume(PendingVolume p);
  void take_label_map(Client& c, const Incoming& in, const std::vector<LabelMetaEntry>& meta);
  void apply_labels(PendingLabels p);
  void answer_image(const PendingVolume& p, int code, const std::string& text);
  void send_edited_or_say_why();
  /// The test fault hook: true when `where` is to fail for the image named `image`.
  bool fault(const char* where, const std::string& image) const {
    return o_.fault_for_test && o_.fault_for_test(where, image);
  }
  std::unique_ptr<Session> stop_session();
  std::string switch_session(std::unique_ptr<Session> next, io::OpenedJournal* next_journal = nullptr,
                             const std::function<io::OpenedJournal(Session&)>& journal_after_stop = {},
                             bool carried = false);
  void take_command(Client& c, const Incoming& in);
  void command_loop();
  void run_command(const Pending& p);
  void answer(const Pending& p, int code, const std::string& text);
  bool submit(session::EditEvent::Kind kind, const session::Brush* brush = nullptr);
  void end_stroke();
  void feed_tool(double dt_s);
  void set_tool(const Command& c);
  void ask_isovalue(const Pending& p);
  void restart_at_isovalue(const Pending& p);
  void save(const Pending& p);
  bool wait_edits_applied(double timeout_s);
  std::shared_ptr<EditMirror> settled_mirror(double timeout_s);
  void send_edited();
  void accept_clients();
  void open_haptic();
  /// What the clients are sent about the device: the servo's force and the volume's frame.
  const RasEcho& echo() const { return echo_device_ ? echo_device_->echo() : device_.echo(); }
  /// Sets stop_, joins `display` and every client thread (after shutting their
  /// connections); idempotent.
  void join_threads(std::thread& display, std::thread& commands) noexcept;
  struct ThreadsJoiner {
    Server& server;
    std::thread& display;
    std::thread& commands;
    ~ThreadsJoiner() { server.join_threads(display, commands); }
  };

  const io::Scene& scene_;
  const IgtlLoop link_loop_ = run::scene_link_loop(scene_);  // what a stream's stiffness is judged by
  ServeOptions o_;
  Log log_;
  Listener listener_;
  run::SceneSetup setup_;
  TransformDevice device_;
  std::unique_ptr<run::HapticDevice> haptic_;  // --haptic: the servo's device (else device_)
  std::unique_ptr<EchoDevice> echo_device_;    // haptic_'s, forwarded, its force kept for the clients
  Counters n_;
  std::atomic<bool> stop_{false};
  std::mutex clients_mu_;
  std::list<Client> clients_;
  std::thread acceptor_;  // accept_clients() until stop_
  int next_id_ = 1;
  std::mutex session_mu_;  // guards session_ (swapped by the main thread, read by the display thread)
  io::OpenedJournal journal_;  // the running session's edit journal (off: null); before session_:
  // destroyed after it, so a session still running while run() unwinds never appends to a freed one
  std::unique_ptr<Session> session_;
  std::uint32_t journal_crc_ = 0;  // the volume journal_ belongs to
  long sessions_ = 0, ticks_ = 0, faults_ = 0, stale_ = 0, missed_ = 0, input_waits_ = 0, input_wait_timeouts_ = 0;
  long disconnected_ = 0, device_faults_ = 0, refused_reports_ = 0;  // the haptic device's ticks
  long uncalibrated_ = 0;  // ticks the haptic device waited for calibration (zero force; not a fault)
  std::mutex stream_mu_;
  std::shared_ptr<Connection> stream_from_;  // the client whose TRANSFORM moved the HIP last
  int stream_owner_ = 0;                     // guarded by stream_mu_: the client that owns the stream (0: none)
  std::int64_t stream_owner_ns_ = 0;         // its last pose [ns, steady]
  std::set<int> stream_denied_;              // clients told the stream is not theirs (this owner)
  StreamReplies replies_{device_, StreamReplyOptions{o_.sched_fifo, o_.stale_s},
                         [this] {
                           std::lock_guard<std::mutex> lock(stream_mu_);
                           return stream_from_;
                         },
                         [this](const std::string& l) { log_.line(l); }};

 public:
  ServeStats stats() const {
    const StreamReplies::Split sp = replies_.split();
    return {ticks_,
            missed_,
            faults_,
            stale_,
            sessions_,
            n_.images.load(),
            replies_.replies(),
            replies_.stall_replies(),
            sp.to_servo_p50_us,
            sp.to_servo_p99_us,
            sp.to_send_p50_us,
            sp.to_send_p99_us,
            double(device_.input_phase().late_ns) * 1e-3,
            input_waits_,
            input_wait_timeouts_,
            replies_.passed_over(),
            device_.overtaken(),
            replies_.dropped(),
            device_.overtaken_gaps()};
  }

 private:
  std::mutex volume_mu_;
  std::mutex image_mu_;  // one IMAGE checked against the memory budget and converted at a time
  // The IMAGE bodies arriving or received from every client and not yet converted or refused
  // (MessageLimits::hold_image), and the session being built for one (swap_volume, an
  // isovalue's restart) [bytes]: counted against the one memory budget.
  std::atomic<std::uint64_t> images_held_bytes_{0};
  std::atomic<std::uint64_t> building_bytes_{0};
  std::optional<PendingVolume> next_volume_;  // a received IMAGE waiting for the main thread
  std::optional<Pending> next_iso_;            // an isovalue command waiting for the main thread
  bool changing_ = false;  // guarded by volume_mu_: the main thread took one of the two and is applying it
  std::mutex labels_mu_;
  // Device names a LBMETA described as label maps, and its elements for each (a later LBMETA
  // naming an image replaces that image's).
  std::map<std::string, std::vector<LabelMetaEntry>> label_images_;
  std::optional<PendingLabels> next_labels_;  // guarded by volume_mu_: a label map for the main thread
  std::mutex cmd_mu_;
  std::deque<Pending> commands_;  // parsed, in arrival order, for the command thread
  // Command thread only: the tool, whether it is applied, the stroke it has open.
  io::BrushSpec tool_;
  bool applying_ = false;
  std::uint64_t stroke_generation_ = 0;  // the session whose stroke is open (0: none)
  StrokeGap stroke_gap_;  // the open stroke's probe out of contact
  bool preparing_ = false;  // guarded by session_mu_: a new session is being built, edits held
  // Main thread: the isovalue a client's `isovalue V` set (a received IMAGE keeps it while
  // inside its values; none: each IMAGE's own, image_isovalue.h).
  std::optional<core::Isosurface> client_iso_;
  std::atomic<bool> save_failed_{false};  // a save command could not write: the exit says so
};

/// The memory a server whose machine's memory is unknown (io::memory_budget_bytes 0, no
/// --memory-mib) may use for its IMAGEs' sessions: 4 GiB (3 GiB of budget: a 512 x 512 x
/// 150 int16 CT with its session), not everything.
constexpr std::uint64_t kUnknownMemoryBytes = std::uint64_t(4) << 30;

/// "isovalue 300 (inside above)".
std::string iso_text(const core::Isosurface& iso) {
  std::ostringstream s;
  s << "isovalue " << iso.tau << " (inside " << core::to_string(iso.inside) << ")";
  return s.str();
}

/// The live field and the renderer at `iso` on a volume of values [lo, hi].
void at_isovalue(const core::Isosurface& iso, float lo, float hi, session::LiveFieldOptions& live, servo::HriParams& hri) {
  live.iso = iso;
  live.background = float(live.iso.outside_value(lo, hi));
  hri.tau = iso.tau;
  hri.inside = iso.inside;
}

std::string mm3(const core::Vec3& v) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << "(" << v.x << ", " << v.y << ", " << v.z << ")";
  return s.str();
}

void Server::refuse(Client& c, const Incoming& in, int code, const std::string& why) {
  n_.refused.fetch_add(1);
  log_.line("refused  client " + std::to_string(c.id) + ", " + in.type + " '" + in.device + "': " + why);
  c.outbox->push(pack_status(code, in.device, why));  // after the answers queued before it
}

void Server::handle(Client& c, Incoming& in) {
  using K = Incoming::Kind;
  switch (in.kind) {
    case K::kImage:
      c.subscribed = true;
      try {
        std::optional<std::vector<LabelMetaEntry>> meta;
        {
          std::lock_guard<std::mutex> lock(labels_mu_);
          if (const auto it = label_images_.find(in.device); it != label_images_.end()) meta = it->second;
        }
        if (meta) {
          take_label_map(c, in, *meta);
          break;
        }
        std::optional<PendingVolume> superseded;
        std::string dims;
        {
          std::lock_guard<std::mutex> image_lock(image_mu_);
          if (const std::string why = memory_refusal(*in.image, in.held_bytes); !why.empty()) {
            refuse(c, in, igtl::StatusMessage::STATUS_RESOURCE_ERROR, why);
            break;
          }
          engine::Volume v = volume_from_image(*in.image);
          dims = std::to_string(v.grid.dims[0]) + " x " + std::to_string(v.grid.dims[1]) + " x " +
                 std::to_string(v.grid.dims[2]);
          std::lock_guard<std::mutex> lock(volume_mu_);
          superseded.swap(next_volume_);
          next_volume_ = PendingVolume{std::move(v), c.outbox, in.device, dims, c.id};
        }
        log_.line("image    client " + std::to_string(c.id) + ", '" + in.device + "': " + dims +
                  " received; its session is built before it is answered");
        if (superseded)
          answer_image(*superseded, igtl::StatusMessage::STATUS_BUSY,
                       "igtl:" + superseded->device + ": not taken: a newer IMAGE ('" + in.device +
                           "') came before its session was built");
      } catch (const std::bad_alloc& e) {
        refuse(c, in, igtl::StatusMessage::STATUS_RESOURCE_ERROR, "igtl:" + in.device + ": " + e.what());
      } catch (const std::exception& e) {
        refuse(c, in, igtl::StatusMessage::STATUS_CONFIG_ERROR, e.what());
      }
      break;
    case K::kTransform:
      n_.transforms.fetch_add(1);
      if (!o_.registration_name.empty() && in.device == o_.registration_name && in.device != o_.stream) {
        take_registration(c, in);
        break;
      }
      if (in.device == o_.stream && !haptic_) {
        if (c.stream_refused) break;  // too slow for the scene's stiffness: its poses move nothing
        if (!own_stream(c, in) || !check_stream_rate(c, in)) break;
        const double t[3] = {in.matrix[0][3], in.matrix[1][3], in.matrix[2][3]};
        if (o_.reply_force) {
          std::lock_guard<std::mutex> lock(stream_mu_);
          stream_from_ = c.conn;
          c.reply_target = true;
        }
        device_.push_mm(t, in.stamp);
      }
      break;
    case K::kString:
      n_.strings.fetch_add(1);
      take_command(c, in);
      break;
    case K::kLabelMeta: {
      std::lock_guard<std::mutex> lock(labels_mu_);
      std::map<std::string, std::vector<LabelMetaEntry>> by_image;
      for (const LabelMetaEntry& e : in.label_meta) by_image[e.image].push_back(e);
      std::string names;
      for (auto& [image, entries] : by_image) {
        names += " '" + image + "' (";
        for (std::size_t i = 0; i < entries.size(); ++i)
          names += (i ? ", " : "") + entries[i].name + " " + std::to_string(entries[i].label);
        names += ")";
        label_images_[image] = std::move(entries);
      }
      log_.line("labels   client " + std::to_string(c.id) + ": label maps" + names +
                " (their IMAGEs become the session's materials)");
      break;
    }
    case K::kSkipped: n_.skipped.fetch_add(1); break;
    case K::kRefused:
      refuse(c, in,
             in.over_budget                           ? igtl::StatusMessage::STATUS_RESOURCE_ERROR
             : in.why.find("CRC") != std::string::npos ? igtl::StatusMessage::STATUS_CHECKSUM_ERROR
                                                       : igtl::StatusMessage::STATUS_CONFIG_ERROR,
             in.why);
      break;
    default: break;
  }
}

/// One client owns the stream: the first whose TRANSFORM came, until it sends none for the
/// stale time (stale_s) or disconnects; then the next one to send takes it (logged). Another
/// client's poses meanwhile move nothing, and it gets one STATUS saying so (once per owner):
/// two trackers on one name no longer make the HIP alternate between them.
bool Server::own_stream(Client& c, const Incoming& in) {
  const std::int64_t now = TransformDevice::now_ns();
  int owner = 0, before = 0;
  bool tell = false;
  {
    std::lock_guard<std::mutex> lock(stream_mu_);
    const bool owner_gone = stream_owner_ == 0 || now - stream_owner_ns_ > std::int64_t(o_.stale_s * 1e9);
    before = stream_owner_;
    if (stream_owner_ == c.id || owner_gone) {
      if (stream_owner_ != c.id) stream_owner_ = c.id, stream_denied_.clear();
      stream_owner_ns_ = now;
    } else {
      tell = stream_denied_.insert(c.id).second;
    }
    owner = stream_owner_;
  }
  if (owner == c.id) {
    if (before != c.id)
      log_.line("stream   '" + o_.stream + "' is client " + std::to_string(c.id) + "'s" +
                (before == 0 ? std::string() : " (client " + std::to_string(before) + "'s stopped)"));
    return true;
  }
  if (tell) {  // outside the lock: the send may wait for the client
    std::ostringstream why;
    why << "stream '" << in.device << "' is client " << owner << "'s (its poses move the HIP until it sends none for "
        << o_.stale_s * 1e3 << " ms or disconnects); this client's poses are ignored";
    refuse(c, in, igtl::StatusMessage::STATUS_ACCESS_DENIED, why.str());
  }
  return false;
}

/// The force loop closes at the stream's rate (as `--haptic igtl:`'s, igtl_device.cpp): at
/// every pose from a client's 16th on, the median time between its latest 16 poses gives its
/// rate, and the scene's servo.stiffness_n_per_m is judged as `--haptic igtl:` judges it
/// (judge_link_stiffness, the scene's loop run::scene_link_loop): against the simulated bound
/// of a wall pressed through a link at min(that rate, the servo's) holding each force one
/// period, plus device.link_round_trip_ms; the bound with the passivity controller when the
/// peer runs it (device.link_passivity_control), without it otherwise; Colgate-Schenkel's
/// 2 (b - |B|) / T is said beside it. The simulation takes 20-30 ms: it runs once per rate
/// bucket per client, in a thread of its own (the pose is not judged until it is known), and
/// is kept: a rate slower than the servo's is simulated at the floor of its 2 % bucket
/// (1.02^floor(log_1.02 rate): at most 2 % slower than measured), one at or above the
/// servo's at the servo's; a stream jittering about a rate meets a few buckets, each
/// simulated once.
/// A stream that slows down later is judged too. A stiffer scene (at 16
/// judgements in a row: a moment's slowdown is not a slow stream) is refused to that client
/// unless allowed (servo.allow_unstable_stiffness, --allow-unstable-stiffness:
/// logged once): a STATUS naming the field, its value, the bounds and the rate; its poses move
/// nothing from then on, so the stream goes stale (zero force). With --reply-force the client
/// (which applies the last Force it got) is sent a zero through the reply thread at once,
/// before that STATUS, not at the stale time (issue 61). The median: a
/// pause in the stream does not make it look slow.
bool Server::check_stream_rate(Client& c, const Incoming& in) {
  constexpr std::size_t kRatePoses = 16;
  constexpr double kRateBucket = 1.02;
  static_assert(kRatePoses == std::tuple_size_v<decltype(c.stream_gaps_ns)> + 1);
  const std::int64_t now = TransformDevice::now_ns();
  if (c.stream_last_ns != 0) c.stream_gaps_ns[c.stream_gap_count++ % c.stream_gaps_ns.size()] = now - c.stream_last_ns;
  c.stream_last_ns = now;
  if (c.stream_gap_count + 1 < kRatePoses) return true;
  std::array<std::int64_t, kRatePoses - 1> g = c.stream_gaps_ns;
  std::nth_element(g.begin(), g.begin() + std::ptrdiff_t(g.size() / 2), g.end());
  const double rate = 1e9 / double(std::max<std::int64_t>(g[g.size() / 2], 1));
  const double sim_hz = rate >= scene_.hri.rate_hz
                            ? scene_.hri.rate_hz
                            : std::pow(kRateBucket, std::floor(std::log(rate) / std::log(kRateBucket)));
  const double k = scene_.hri.stiffness_n_per_m;
  // A rate not simulated yet is simulated in a thread of its own: in this one, the
  // simulation's stall would make the poses queued behind it look like a slower stream (a
  // new bucket, another stall). Until its bound is known, a pose is not judged (the
  // judgements over the bound in a row neither grow nor restart).
  if (c.stream_bound_next.valid() &&
      c.stream_bound_next.wait_for(std::chrono::seconds(0)) == std::future_status::ready) {
    const LinkStiffness& n = c.stream_bounds.emplace(c.stream_bound_next_hz, c.stream_bound_next.get()).first->second;
    std::ostringstream s;
    s << "stream   client " << c.id << ": the loop closing at " << n.loop_hz
      << " Hz: Colgate-Schenkel 2 (b - |B|) / T = " << std::lround(n.colgate_n_per_m) << " N/m; " << n.text
      << "; the scene's K " << k << " N/m is " << (n.over ? "above" : "within") << " it";
    log_.line(s.str());
  }
  const auto at = c.stream_bounds.find(sim_hz);
  if (at == c.stream_bounds.end()) {
    if (!c.stream_bound_next.valid()) {
      c.stream_bound_next_hz = sim_hz;
      // The test seam: the simulation of a rate throws ("link:DEVICE@HZ", HZ the bucket's, whole).
      const bool fail = fault("link", in.device + "@" + std::to_string(std::lround(sim_hz)));
      c.stream_bound_next = std::async(std::launch::async, [loop = link_loop_, sim_hz, fail] {
        if (fail) throw std::bad_alloc();
        return judge_link_stiffness(loop, sim_hz);
      });
    }
    return true;
  }
  const LinkStiffness& j = at->second;
  if (!j.over) {
    c.stream_over = 0;
    return true;
  }
  // Over the bound at 16 judgements in a row (16 more poses): a moment's slowdown of a
  // loaded client is not a slow stream.
  if (++c.stream_over < kRatePoses) return true;
  if (scene_.allow_unstable_stiffness && c.stream_warned) return true;
  const double b = link_loop_.handle_damping_n_s_per_m;
  std::ostringstream why;
  why << "stream '" << in.device << "' at " << std::lround(rate) << " Hz (median of its latest " << kRatePoses
      << " poses): servo.stiffness_n_per_m " << k << " is above the bound " << std::lround(j.limit_n_per_m) << " N/m "
      << (link_loop_.peer_passivity_control ? "with" : "without")
      << " the passivity controller at the peer's end with the loop closing at " << j.loop_hz
      << " Hz (the stream's rate, to its 2 % bucket's floor, or the servo's); " << j.text
      << "; Colgate-Schenkel 2 (b - |B|) / T = " << std::lround(j.colgate_n_per_m) << " N/m (b " << b << " N s/m, B "
      << scene_.hri.damping_n_s_per_m << " N s/m)";
  if (scene_.allow_unstable_stiffness) {
    log_.line("stream   client " + std::to_string(c.id) + ": warning: " + why.str() + " (allowed)");
    c.stream_warned = true;
    return true;
  }
  const bool pc_would = !link_loop_.peer_passivity_control && !(k > j.bound.k_max_with_pc_n_per_m);
  why << "; the contact may buzz: its poses move nothing (lower the stiffness, raise the stream's rate, "
      << (pc_would ? "run the passivity controller on the peer and say so (the scene's device.link_passivity_control: "
                     "true), "
                   : "")
      << "or allow it: --allow-unstable-stiffness, or the scene's servo.allow_unstable_stiffness)";
  c.stream_refused = true;
  log_.line("stream   client " + std::to_string(c.id) + " refused: " + why.str());
  leave_stream_zero(c, "its refusal");  // before its STATUS
  refuse(c, in, igtl::StatusMessage::STATUS_CONFIG_ERROR, why.str());
  return false;
}

/// With --reply-force, a client that stops being the stream's (refused, or dropped by an
/// exception in its thread) applies the last Force it got: it is sent a zero at once, through
/// the reply thread, before `before` (its STATUS, or its connection's shutdown).
void Server::leave_stream_zero(Client& c, const std::string& before) {
  if (!o_.reply_force) return;
  {
    std::lock_guard<std::mutex> lock(stream_mu_);
    if (stream_from_ == c.conn) stream_from_.reset();
  }
  const long zeros = replies_.retarget_zeros();
  if (!replies_.retarget(1.0))
    log_.line("stream   client " + std::to_string(c.id) + ": the reply thread did not send its zero within 1 s");
  else if (replies_.retarget_zeros() > zeros)
    log_.line("stream   client " + std::to_string(c.id) + ": a zero Force sent to it before " + before);
}

/// A TRANSFORM named registration_name: the tracker's registration to the image from now on
/// (the stream's poses, the Force replies), answered with a STATUS; one that is not rigid
/// is refused and the registration kept.
void Server::take_registration(Client& c, const Incoming& in) {
  if (haptic_)
    return refuse(c, in, igtl::StatusMessage::STATUS_CONFIG_ERROR,
                  "registration '" + in.device + "': the device is --haptic " + o_.haptic + ", not the TRANSFORM stream");
  Registration r;
  try {
    r = registration_from_matrix(in.matrix);
  } catch (const std::exception& e) {
    return refuse(c, in, igtl::StatusMessage::STATUS_CONFIG_ERROR,
                  "registration '" + in.device + "': " + e.what() + "; the registration is unchanged");
  }
  device_.set_registration(r);
  const std::string text = "registration taken: tracker -> image " + r.describe();
  log_.line("register client " + std::to_string(c.id) + ", '" + in.device + "': " + r.describe());
  c.conn->send(pack_status(igtl::StatusMessage::STATUS_OK, in.device, text));
}

/// A client gone gives the stream up at once.
void Server::release_stream(int client) {
  bool owned = false;
  {
    std::lock_guard<std::mutex> lock(stream_mu_);
    owned = stream_owner_ == client;
    if (owned) stream_owner_ = 0;
    stream_denied_.erase(client);
  }
  if (owned) log_.line("stream   '" + o_.stream + "' free: its client " + std::to_string(client) + " is gone");
}

void Server::client_loop(Client& c) {
  bool dropped = true;
  try {
    read_messages(c);
    dropped = false;
  } catch (const std::exception& e) {  // e.g. bad_alloc: this client is dropped, the server goes on
    log_.line("client   " + std::to_string(c.id) + " dropped: " + e.what());
  } catch (...) {
    log_.line("client   " + std::to_string(c.id) + " dropped: an unknown exception");
  }
  if (dropped) leave_stream_zero(c, "its connection closed");  // it would hold the last Force it got
  log_.line("client   " + std::to_string(c.id) + " gone");
  release_stream(c.id);
  c.conn->shutdown();
  // A link simulation still running ends here, not in the reaper's erase (under clients_mu_,
  // which the display loop takes: a 20-60 ms wait there).
  if (c.stream_bound_next.valid()) c.stream_bound_next.wait();
  c.done = true;
}

void Server::read_messages(Client& c) {
  for (;;) {
    Incoming in = read_message(*c.conn, o_.limits);
    if (in.kind == Incoming::Kind::kClosed) break;
    if (in.kind == Incoming::Kind::kBroken) {
      n_.broken.fetch_add(1);
      refuse(c, in, igtl::StatusMessage::STATUS_CONFIG_ERROR, in.why + "; closing the connection");
      c.outbox->flush(o_.receive_timeout_ms);  // the STATUS goes before the connection
      break;
    }
    handle(c, in);
  }
}

/// The accept thread: takes connections throughout, while the main thread builds a volume's
/// session too, and frees the slots of the clients gone. With every slot taken, a new
/// connection gets the slot of the client quiet longest (evict_quietest), else is refused.
void Server::accept_clients() {
  const int fd = listener_.accept(50);
  std::lock_guard<std::mutex> lock(clients_mu_);
  for (auto it = clients_.begin(); it != clients_.end();) {  // reap the finished
    if (it->done) {
      it->thread.join();
      it->outbox->close();  // its reader ended (the connection shut): nothing more to send
      it = clients_.erase(it);
    } else {
      ++it;
    }
  }
  if (fd < 0) return;
  const auto taken = std::count_if(clients_.begin(), clients_.end(), [](const Client& c) { return !c.evicted; });
  if (taken >= o_.max_clients && !evict_quietest()) return refuse_connection(fd);
  Client& c = clients_.emplace_back();
  try {
    c.id = next_id_++;
    c.conn = std::make_shared<Connection>(fd, o_.receive_timeout_ms, o_.message_timeout_ms, &stop_);
  } catch (...) {
    ::close(fd);
    clients_.pop_back();
    throw;
  }
  try {
    c.outbox = std::make_shared<Outbox>(c.conn, kOutboxBytes, [this, id = c.id](const std::string& why) {
      n_.dropped_clients.fetch_add(1);
      log_.line("client   " + std::to_string(id) + " dropped: " + why);
    });
    n_.clients.fetch_add(1);
    log_.line("client   " + std::to_string(c.id) + " connected");
    c.thread = std::thread([this, &c] { client_loop(c); });
  } catch (...) {  // the slot is not kept: the connection closes with its Connection
    if (c.outbox) c.outbox->close();
    clients_.pop_back();
    throw;
  }
}

/// Every slot taken and a new connection: the client quiet longest (no byte received for at
/// least --idle-timeout-s), if any, is closed and its slot counted as free. Never a session's
/// client (it sent an IMAGE or a command: it may only read for long); a client only quiet is
/// never closed while nobody needs its slot (3D Slicer watching the TRANSFORMs sends nothing).
/// Under clients_mu_.
bool Server::evict_quietest() {
  if (o_.idle_timeout_s <= 0) return false;
  const auto least_ms = std::int64_t(std::min(o_.idle_timeout_s, 1e6) * 1000);
  Client* quietest = nullptr;
  std::int64_t quietest_ms = 0;
  for (Client& c : clients_) {
    if (c.evicted || c.done || c.subscribed || !c.conn->alive()) continue;
    const std::int64_t ms = c.conn->quiet_ms();
    if (ms >= least_ms && ms > quietest_ms) quietest = &c, quietest_ms = ms;
  }
  if (!quietest) return false;
  quietest->evicted = true;
  quietest->conn->shutdown();  // its reader ends, its thread is reaped with the finished
  n_.idle.fetch_add(1);
  std::ostringstream s;
  s << "client   " << quietest->id << " closed: quiet for " << std::fixed << std::setprecision(1)
    << double(quietest_ms) / 1000 << " s, its slot given to a new connection";
  log_.line(s.str());
  return true;
}

/// One connection past max_clients: a STATUS saying so (never waited for), then closed.
void Server::refuse_connection(int fd) {
  Connection extra(fd, o_.receive_timeout_ms, o_.message_timeout_ms, &stop_);
  const std::string why = "the server has its " + std::to_string(o_.max_clients) + " clients; connection refused";
  extra.send_droppable(pack_status(igtl::StatusMessage::STATUS_NOT_READY, "", why));
  n_.refused.fetch_add(1);
  log_.line("refused  a connection: " + why);
}

void Server::take_command(Client& c, const Incoming& in) {
  c.subscribed = true;
  auto parsed = parse_command(in.text);
  if (auto* why = std::get_if<std::string>(&parsed)) {
    const bool unknown = why->rfind("unknown command", 0) == 0 || why->rfind("empty command", 0) == 0;
    return refuse(c, in, unknown ? igtl::StatusMessage::STATUS_UNKNOWN_INSTRUCTION : igtl::StatusMessage::STATUS_CONFIG_ERROR,
                  *why);
  }
  std::lock_guard<std::mutex> lock(cmd_mu_);
  commands_.push_back({std::get<Command>(parsed), c.outbox, in.device, c.id});
}

void Server::answer(const Pending& p, int code, const std::string& text) {
  n_.commands.fetch_add(1);
  if (code != igtl::StatusMessage::STATUS_OK) n_.refused.fetch_add(1);
  log_.line(std::string(code == igtl::StatusMessage::STATUS_OK ? "command  " : "refused  ") + "client " +
            std::to_string(p.client) + ", " + text);
  p.from->push(pack_status(code, p.device, text));  // never waited for: a client not reading is dropped
}

/// Submits one edit to the running session (command thread: the session's one API producer).
bool Server::submit(session::EditEvent::Kind kind, const session::Brush* brush) {
  std::lock_guard<std::mutex> lock(session_mu_);
  if (!session_) return false;
  session::EditEvent e;
  e.kind = kind;
  if (brush) e.brush = *brush;
  if (preparing_) return false;  // a new volume is being built: no GPU work beside it
  if (kind == session::EditEvent::Kind::kBeginStroke) stroke_generation_ = session_->generation;
  if (kind == session::EditEvent::Kind::kEndStroke && stroke_generation_ != session_->generation) return false;
  if (kind == session::EditEvent::Kind::kEndStroke) stroke_generation_ = 0;
  return session_->live().submit(e);
}

void Server::end_stroke() {
  if (stroke_generation_ != 0) submit(session::EditEvent::Kind::kEndStroke);
  stroke_generation_ = 0;
  stroke_gap_.reset();
}

/// While applying: one brush of the tool at the proxy per command tick in contact, over
/// `dt_s` (tool_dt): a press opens a stroke, one undo step; out of contact for kStrokeGapS
/// closes it (tool_ticks.h).
void Server::feed_tool(double dt_s) {
  if (!applying_) return;
  std::optional<session::Brush> brush;
  std::uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (!session_) return;
    const session::Observed ob = session_->live().observe();
    generation = session_->generation;
    if (ob.tick >= 0 && ob.contact)
      brush = run::make_brush(run::brush_at_tool(scene_, session_->frame, tool_), session_->targets, ob.vhip_m, dt_s,
                              core::norm(ob.force_n));
  }
  if (!brush) {
    if (stroke_gap_.out_of_contact(dt_s) || stroke_generation_ != generation) end_stroke();
    return;
  }
  stroke_gap_.in_contact();
  if (stroke_generation_ != generation) submit(session::EditEvent::Kind::kBeginStroke);
  submit(session::EditEvent::Kind::kBrush, &*brush);
}

void Server::set_tool(const Command& c) {
  tool_.kind = c.tool;
  if (c.radius_mm > 0) tool_.radius_mm = c.radius_mm;
  if (c.strength > 0) (c.tool == "drill" ? tool_.rate : tool_.strength) = c.strength;
  if (c.tool == "smooth") tool_.strength = std::min(tool_.strength, 1.0);
}

/// Checks the isovalue against the volume's range; the main thread restarts the session.
void Server::ask_isovalue(const Pending& p) {
  float lo = 0, hi = 0;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (session_) lo = session_->frame.min_value, hi = session_->frame.max_value;
  }
  if (!(p.cmd.value > lo && p.cmd.value < hi)) {
    std::ostringstream s;
    s << "isovalue " << p.cmd.value << ": outside the volume's value range (" << lo << ", " << hi << ")";
    return answer(p, igtl::StatusMessage::STATUS_CONFIG_ERROR, s.str());
  }
  end_stroke();
  std::lock_guard<std::mutex> lock(volume_mu_);
  next_iso_ = p;
}

/// True once every edit submitted so far was applied or refused (save sees them all).
namespace {
/// Every edit submitted to the session has been applied (its bricks in the mirror: the
/// count follows the listener), refused, dropped or merged (a stroke's end whose begin the
/// full queue dropped).
bool edits_settled(const session::LiveStats& st) { return st.settled(); }
}  // namespace

bool Server::wait_edits_applied(double timeout_s) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(session_mu_);
      if (!session_) return true;
      if (edits_settled(session_->live().stats(0))) return true;
    }
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

/// The session's edited volume once nothing is in flight: no received IMAGE or isovalue
/// waiting for or being applied by the main thread (a save after them saves their result, and
/// never meets the moment between the old session's stop and the new one's start), and every
/// edit submitted applied or refused. Null if that does not happen within `timeout_s`.
std::shared_ptr<EditMirror> Server::settled_mirror(double timeout_s) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  for (;;) {
    bool changing;
    {
      std::lock_guard<std::mutex> lock(volume_mu_);
      changing = changing_ || next_volume_ || next_iso_;
    }
    if (!changing) {
      std::lock_guard<std::mutex> lock(session_mu_);
      if (session_ && !preparing_) {
        if (edits_settled(session_->live().stats(0))) return session_->mirror;
      }
    }
    if (std::chrono::steady_clock::now() > until) return nullptr;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

void Server::save(const Pending& p) {
  end_stroke();
  const std::string path = (std::filesystem::path(o_.save_dir) / p.cmd.file).string();
  if (!io::volume_writable(p.cmd.file))
    return answer(p, igtl::StatusMessage::STATUS_CONFIG_ERROR,
                  "save name '" + p.cmd.file + "': not a format written (.vdb, .mha, .nrrd, .nii, .nii.gz)");
  const std::shared_ptr<EditMirror> mirror = settled_mirror(30.0);
  if (!mirror)
    return answer(p, igtl::StatusMessage::STATUS_NOT_READY,
                  "save " + p.cmd.file + ": the session's edits did not settle in 30 s");
  try {
    io::save_any_volume(mirror->volume(), path, io::SaveVdbOptions{});
    answer(p, igtl::StatusMessage::STATUS_OK, "save " + p.cmd.file + ": wrote " + path);
  } catch (const std::exception& e) {
    save_failed_ = true;
    answer(p, igtl::StatusMessage::STATUS_RESOURCE_ERROR, "save " + p.cmd.file + ": " + e.what());
  }
}

void Server::run_command(const Pending& p) {
  using K = Command::Kind;
  const std::string what = to_string(p.cmd);
  switch (p.cmd.kind) {
    case K::kIsovalue: return ask_isovalue(p);
    case K::kSave: return save(p);
    case K::kTool: set_tool(p.cmd); break;
    case K::kApply: applying_ = true; break;
    case K::kStop:
      applying_ = false;
      end_stroke();
      break;
    case K::kUndo:
    case K::kRedo:
      end_stroke();
      if (!submit(p.cmd.kind == K::kUndo ? session::EditEvent::Kind::kUndo : session::EditEvent::Kind::kRedo))
        return answer(p, igtl::StatusMessage::STATUS_BUSY, what + ": the session's edit queue is full");
      break;
  }
  answer(p, igtl::StatusMessage::STATUS_OK, what + ": done");
}

/// send_edited(); when it throws (std::bad_alloc copying or packing the volume), a line and a
/// STATUS to the subscribed clients say so, and the changed voxels wait for the next try.
void Server::send_edited_or_say_why() {
  std::exception_ptr error;
  try {
    send_edited();
    return;
  } catch (...) {
    error = std::current_exception();
  }
  try {
    std::string what = "an unknown exception";
    try {
      std::rethrow_exception(error);
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
    }
    std::string name;
    {
      std::lock_guard<std::mutex> lock(session_mu_);
      name = session_ ? session_->image_name : "isotouch";
    }
    const std::string why = "edited '" + name + "': the edited voxels could not be sent (" + what +
                            "); they go with the next IMAGE";
    log_.line("refused  " + why);
    const std::vector<std::uint8_t> status = pack_status(igtl::StatusMessage::STATUS_RESOURCE_ERROR, name, why);
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (Client& c : clients_)
      if (c.subscribed && !c.done && c.conn->alive()) c.conn->send_droppable(status);
  } catch (...) {  // no memory even for the line: the next tick tries again
  }
}

/// The voxels changed since the last call, as an IMAGE to every subscribed client.
void Server::send_edited() {
  std::shared_ptr<EditMirror> mirror;
  std::string name;
  engine::Volume frame;  // the grid and direction, no voxels
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (!session_) return;
    mirror = session_->mirror;
    name = session_->image_name;
    frame = session_->frame;
  }
  const VoxelBox box = mirror->take_changed();  // nothing changed: nothing copied, nothing sent
  if (box.empty()) return;
  VoxelBox part = box;
  if (o_.image_whole) part.lo = {0, 0, 0}, part.hi = frame.grid.dims;
  Outbox::Bytes bytes;
  try {
    if (fault("edited", name)) throw std::bad_alloc();
    // The voxels copied straight into the IMAGE, the mirror's lock held a slice at a time.
    bytes = std::make_shared<const std::vector<std::uint8_t>>(
        pack_image(frame, name, part, [&](float* out) { mirror->copy_box(part, out); }));
  } catch (...) {
    mirror->restore_changed(box);  // these voxels go with the next IMAGE
    throw;
  }
  std::vector<std::shared_ptr<Outbox>> to;
  {
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (Client& c : clients_)
      if (c.subscribed && !c.done && c.conn->alive()) to.push_back(c.outbox);
  }
  int sent = 0;  // queued: each client's thread sends it, a client not reading is dropped
  for (auto& c : to) sent += c->push(bytes);
  n_.images_sent.fetch_add(sent);
  std::ostringstream s;
  s << "edited   '" << name << "' voxels [" << box.lo[0] << ", " << box.hi[0] << ") x [" << box.lo[1] << ", " << box.hi[1]
    << ") x [" << box.lo[2] << ", " << box.hi[2] << ") sent as " << (o_.image_whole ? "the whole image" : "a sub-volume")
    << " (" << bytes->size() << " bytes) to " << sent << " of " << to.size() << " clients";
  log_.line(s.str());
}

/// The command thread: the commands received, then the tool, once a display period; one that
/// fell behind does not catch up in a burst of tool ticks (next_tick, tool_dt: tool_ticks.h).
void Server::command_loop() {
  using Clock = std::chrono::steady_clock;
  const double period_s = 1.0 / o_.display_hz;
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_s));
  auto next = Clock::now();
  auto next_image = next;
  auto last_tool = next;
  while (!stop_) {
    std::this_thread::sleep_until(next);
    std::deque<Pending> todo;
    {
      std::lock_guard<std::mutex> lock(cmd_mu_);
      todo.swap(commands_);
    }
    // What a command, the tool or the edited IMAGE throws (std::bad_alloc) is answered or
    // logged here: the command thread, and with it the server and the device's force, go on.
    for (const Pending& p : todo) {
      try {
        run_command(p);
      } catch (const std::exception& e) {
        try {
          answer(p, igtl::StatusMessage::STATUS_RESOURCE_ERROR, to_string(p.cmd) + ": failed (" + e.what() + ")");
        } catch (...) {
        }
      }
    }
    try {
      const double since_s = std::chrono::duration<double>(Clock::now() - last_tool).count();
      last_tool = Clock::now();
      feed_tool(tool_dt(since_s, period_s));
    } catch (const std::exception& e) {
      try {
        log_.line(std::string("tool     not applied this tick: ") + e.what());
      } catch (...) {
      }
    }
    if (o_.image_hz > 0 && std::chrono::steady_clock::now() >= next_image) {
      send_edited_or_say_why();
      next_image = std::chrono::steady_clock::now() +
                   std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(1.0 / o_.image_hz));
    }
    next = next_tick(next, Clock::now(), period);  // after the work: a save that took seconds is not followed by a burst
  }
}

void Server::display_loop() {
  const auto period = std::chrono::duration<double>(1.0 / o_.display_hz);
  auto next = std::chrono::steady_clock::now();
  const double stall_s = std::max(0.05, 4.0 / scene_.hri.rate_hz);
  while (!stop_) {
    next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
    std::this_thread::sleep_until(next);
    try {
      display_tick(stall_s);
    } catch (const std::exception& e) {  // e.g. std::bad_alloc: this tick's transforms are not sent
      try {
        log_.line(std::string("display  a tick not sent: ") + e.what());
      } catch (...) {
      }
    }
  }
}

/// One display tick: HIP, Proxy and Force to every client.
void Server::display_tick(double stall_s) {
  std::vector<std::uint8_t> out, points;  // HIP, Proxy and Force; HIP and Proxy
  long n_out = 0, n_points = 0;            // the TRANSFORMs in each
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (!session_) return;
    const session::Observed ob = session_->live().observe();
    if (ob.tick < 0) return;
    const core::Vec3 hip = echo().grid_to_ras_mm(ob.hip_m), vhip = echo().grid_to_ras_mm(ob.vhip_m);
    const core::Vec3 f = echo().force_ras_n(stall_s);
    for (const auto& [name, v] : {std::pair{"HIP", hip}, std::pair{"Proxy", vhip}, std::pair{"Force", f}}) {
      // No fresh pose (none yet, a pause past the stale time, the tracker gone): the servo
      // rendered nothing, and its HIP and proxy are no place (the proxy a zero, the HIP the
      // origin before the first pose). Not sent: the clients keep the last true ones. The
      // force (zero then) is sent.
      if (!ob.rendered && std::string(name) != "Force") continue;
      const double t[3] = {v.x, v.y, v.z};
      const auto b = pack_translation(name, t);
      if (std::string(name) == "Force") points = out, n_points = n_out;
      out.insert(out.end(), b.begin(), b.end());
      ++n_out;
    }
  }
  // With --reply-force a stream's client applies every Force it gets (PLUS): it gets its
  // forces from the reply thread alone (the stall rule, the last zero), not this display
  // copy, also once another client took the stream over.
  std::lock_guard<std::mutex> lock(clients_mu_);
  for (Client& c : clients_) {
    if (c.done || !c.conn->alive()) continue;
    const bool to_stream = c.reply_target.load();
    const std::vector<std::uint8_t>& bytes = to_stream ? points : out;
    if (bytes.empty()) continue;  // a stream's client, and no fresh pose: nothing to send
    const long n = to_stream ? n_points : n_out;
    switch (c.conn->try_send(bytes)) {
      case Sent::kSent: n_.sent.fetch_add(n); break;
      case Sent::kFull: n_.dropped_sends.fetch_add(n); break;  // not reading
      case Sent::kBusy: n_.busy_sends.fetch_add(n); break;     // its Outbox or reply under way
      case Sent::kDead: break;
    }
  }
}

/// A session on `v`, built (its snapshot, field, renderer) but not started: the running
/// one goes on meanwhile.
std::unique_ptr<Session> Server::prepare_session(engine::Volume v, const session::LiveFieldOptions& live,
                                                 const servo::HriParams& hri) {
  auto s = std::make_unique<Session>();
  s->mirror = std::make_shared<EditMirror>(v);
  s->frame.grid = v.grid;
  s->frame.direction = v.direction;
  s->frame.direction_is_identity = v.direction_is_identity;
  s->frame.min_value = v.min_value;
  s->frame.max_value = v.max_value;
  s->targets = session::default_targets(v, live.iso);
  s->image_name = v.path.rfind("igtl:", 0) == 0 ? v.path.substr(5) : "isotouch";
  if (fault("prepare", s->image_name)) throw std::bad_alloc();
  // The renderer's force is stiffness x depth / world_per_device: the TRANSFORM stream's map
  // is the identity (its points are the volume's own), so its renderer must not scale by the
  // scene's workspace_scale (at 0.1 that was 10x the stiffness the stability check saw); a
  // `--haptic` device is mapped with the scale (start_session), and its renderer scales.
  session::SessionOptions so;
  so.field = live;
  so.hri = hri;
  if (!echo_device_) so.hri.world_per_device = 1.0;
  so.vk = setup_.vk.get();
  so.history_limit_mib = scene_.edits.history_limit_mib;
  session::Opened opened = session::Session::open(std::move(v), so);
  opened.throw_if_failed();
  s->parts = std::move(opened.session);
  return s;
}

void Server::start_session(std::unique_ptr<Session> s) {
  session::LiveSessionConfig c;
  c.servo.rate_hz = scene_.hri.rate_hz;
  c.servo.force_limit_n = scene_.hri.force_limit_n;  // the gate: min(scene, device)
  c.servo.passivity_control = scene_.passivity_control;
  c.servo.sched_fifo = c.servo.pin_cpu = c.servo.lock_memory = o_.sched_fifo;
  if (echo_device_) {  // no servo runs now
    echo_device_->echo().set_frame(s->frame);
    c.servo.world_T_device = {scene_.workspace_scale, s->frame.grid.centre_m()};  // as setup_scene's
  } else {
    device_.set_frame(s->frame, o_.offset_mm);
    device_.set_max_force_n(scene_.link_max_force_n);  // the gate clamps to min(scene, link)
    c.servo.stale_timeout_s = o_.stale_s;
  }
  c.on_applied = s->mirror->listener(s->parts->edits());
  if (s->journal)
    c.on_applied = [j = s->journal, mirror = std::move(c.on_applied)](
                       const session::EditEvent& e, const session::EditOutcome& out, session::EditSource source) {
      if (out.error.empty()) j->append(e);  // what a recording records: the edits applied
      mirror(e, out, source);
    };
  servo::HapticDeviceIO& device = echo_device_ ? static_cast<servo::HapticDeviceIO&>(*echo_device_) : device_;
  s->parts->attach(device, std::move(c)).throw_if_failed();
  if (const std::string note = s->live().start(); !note.empty()) log_.line("servo    " + note);
  if (fault("start", s->image_name)) throw std::bad_alloc();  // (s->live stops as it unwinds)
  ++sessions_;
  std::lock_guard<std::mutex> lock(session_mu_);
  s->generation = std::uint64_t(sessions_);
  session_ = std::move(s);
}

/// While it lives, the command thread submits no edit (Server::submit): a new session is
/// being built on the GPU context the running one edits with.
struct HoldEdits {
  std::mutex& mu;
  bool& preparing;
  HoldEdits(std::mutex& m, bool& p) : mu(m), preparing(p) {
    std::lock_guard<std::mutex> lock(mu);
    preparing = true;
  }
  ~HoldEdits() {
    std::lock_guard<std::mutex> lock(mu);
    preparing = false;
  }
  HoldEdits(const HoldEdits&) = delete;
  HoldEdits& operator=(const HoldEdits&) = delete;
};

/// A session being built, counted against the memory budget while it lives.
struct BuildingBytes {
  std::atomic<std::uint64_t>& bytes;
  std::uint64_t n;
  BuildingBytes(std::atomic<std::uint64_t>& b, std::uint64_t k) : bytes(b), n(k) { bytes.fetch_add(n); }
  ~BuildingBytes() { bytes.fetch_sub(n); }
  BuildingBytes(const BuildingBytes&) = delete;
  BuildingBytes& operator=(const BuildingBytes&) = delete;
};

/// How long the running session's edits may take to settle before a new session is built;
/// past it the change is refused (never built beside edits still running: the two would
/// share the GPU context's one queue, pool and fence).
constexpr double kSettleS = 5.0;

/// A label map IMAGE (a LBMETA named it, `meta` its elements): checked against the running
/// session's grid and its labels here, then handed to the main thread (apply_labels), which
/// answers it. What is wrong is refused with a STATUS naming the field and both values.
void Server::take_label_map(Client& c, const Incoming& in, const std::vector<LabelMetaEntry>& meta) {
  engine::Volume frame;
  std::uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (session_) frame = session_->frame, generation = session_->generation;
  }
  if (generation == 0)
    return refuse(c, in, igtl::StatusMessage::STATUS_NOT_READY, "igtl:" + in.device + ": no session for its labels yet");
  std::shared_ptr<const materials::LabelVolume> lv;
  {
    std::lock_guard<std::mutex> image_lock(image_mu_);
    if (const std::string why = memory_refusal(*in.image, in.held_bytes); !why.empty())
      return refuse(c, in, igtl::StatusMessage::STATUS_RESOURCE_ERROR, why);
    const engine::Volume labels = label_map_from_image(*in.image);
    lv = std::make_shared<const materials::LabelVolume>(
        labels_from_image(labels, in.device, meta, frame, scene_.materials.list));
  }
  log_.line("labels   client " + std::to_string(c.id) + ", '" + in.device + "': a label map on the volume's grid, " +
            std::to_string(lv->materials.size()) + " materials; the session takes them once its edits settle");
  std::optional<PendingLabels> superseded;
  {
    std::lock_guard<std::mutex> lock(volume_mu_);
    superseded.swap(next_labels_);
    next_labels_ = PendingLabels{std::move(lv), c.outbox, in.device, generation, c.id};
  }
  if (superseded) {
    n_.refused.fetch_add(1);
    superseded->from->push(pack_status(igtl::StatusMessage::STATUS_BUSY, superseded->device,
                                       "igtl:" + superseded->device + ": not taken: a newer label map ('" + in.device +
                                           "') came before the session took it"));
  }
}

/// Main thread: the label map's materials become the running session's (the drill's cut per
/// material, the names and colours in the log and the STATUS), its edits held and settled
/// first; refused when the session it was checked against is gone (a new volume came).
void Server::apply_labels(PendingLabels p) {
  auto answer_labels = [&](int code, const std::string& text) {
    if (code != igtl::StatusMessage::STATUS_OK) {
      n_.refused.fetch_add(1);
      log_.line("refused  client " + std::to_string(p.client) + ", IMAGE '" + p.device + "': " + text);
    }
    p.from->push(pack_status(code, p.device, text));
  };
  const HoldEdits hold(session_mu_, preparing_);
  const std::string keep = "; the session goes on with the materials it had";
  if (!wait_edits_applied(kSettleS))
    return answer_labels(igtl::StatusMessage::STATUS_BUSY,
                         "igtl:" + p.device + ": not taken: the running session's edits did not settle" + keep);
  Session* s = nullptr;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (session_ && session_->generation == p.generation) s = session_.get();
  }
  if (!s)
    return answer_labels(igtl::StatusMessage::STATUS_NOT_READY,
                         "igtl:" + p.device + ": not taken: the session's volume changed since it came; send it again");
  try {
    s->parts->edits().sculptor().set_material_cut(run::material_cut(*p.labels));
  } catch (const std::exception& e) {
    return answer_labels(igtl::StatusMessage::STATUS_CONFIG_ERROR, "igtl:" + p.device + ": not taken: " + e.what() + keep);
  }
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    s->labels = p.labels;
  }
  const std::string what = describe_materials(*p.labels);
  log_.line("materials client " + std::to_string(p.client) + ", '" + p.device + "': " +
            std::to_string(p.labels->materials.size()) + " from " + p.labels->source + ": " + what + "; " +
            std::to_string(p.labels->voxels[0]) + " voxels unlabelled (the drill cuts per material, never the "
            "critical ones; the servo does not feel materials yet)");
  for (const std::string& n : p.labels->notes) log_.line("         note: " + n);
  n_.label_maps.fetch_add(1);
  answer_labels(igtl::StatusMessage::STATUS_OK, "label map taken: " + std::to_string(p.labels->materials.size()) +
                                                    " materials: " + what);
}

/// `isovalue V` (checked by the command thread): the session restarts on its edited volume
/// at V (the renderer, the live field's active bricks and the tool's targets follow it; the
/// undo history starts afresh). The new session is built first, while the old one serves
/// with its edits held: when it cannot be built the isovalue is refused and nothing changes.
void Server::restart_at_isovalue(const Pending& p) {
  std::shared_ptr<EditMirror> mirror;
  std::shared_ptr<const materials::LabelVolume> labels;  // a client's label map: kept (same grid)
  std::string name;
  std::uint64_t voxels = 0;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (session_) mirror = session_->mirror, name = session_->image_name, voxels = session_->frame.grid.voxel_count();
    if (session_) labels = session_->labels;
  }
  if (!mirror) return answer(p, igtl::StatusMessage::STATUS_NOT_READY, "isovalue: no session");
  const HoldEdits hold(session_mu_, preparing_);
  const std::string what = to_string(p.cmd);
  std::ostringstream settle;
  settle << what << ": the session's edits did not settle in " << kSettleS << " s; the isovalue is unchanged";
  if (!wait_edits_applied(kSettleS) || fault("settle", name))
    return answer(p, igtl::StatusMessage::STATUS_BUSY, settle.str());
  std::unique_ptr<Session> next;
  session::LiveFieldOptions live = setup_.live;
  servo::HriParams hri = setup_.hri;
  const BuildingBytes building(building_bytes_, voxels * session_bytes_per_voxel());
  try {
    engine::Volume v = mirror->volume();  // every edit applied: the edited volume
    v.path = name == "isotouch" ? v.path : "igtl:" + name;
    live.iso.tau = p.cmd.value;
    live.background = float(live.iso.outside_value(v.min_value, v.max_value));
    hri.tau = p.cmd.value;
    next = prepare_session(std::move(v), live, hri);
    if (labels) next->parts->edits().sculptor().set_material_cut(run::material_cut(*labels)), next->labels = labels;
    else if (setup_.cut && name == "isotouch") next->parts->edits().sculptor().set_material_cut(setup_.cut);
  } catch (const std::exception& e) {
    return answer(p, igtl::StatusMessage::STATUS_RESOURCE_ERROR,
                  what + ": the session could not be rebuilt at it (" + e.what() + "); the isovalue is unchanged");
  }
  // The session's journal goes on in the same file (its volume's: the one a restore is
  // offered for), its edits so far kept and the new isovalue and history restart in its header.
  io::OpenedJournal journal;
  const std::optional<core::Isosurface> journal_iso = live.iso;
  std::function<io::OpenedJournal(Session&)> carry;
  if (journal_.journal)
    carry = [this, journal_iso](Session& s) {
      std::vector<std::size_t> restarts = journal_.history_restarts;
      restarts.push_back(std::size_t(-1));  // carry_journal: at the edits so far
      return carry_journal(journal_, s, journal_iso, restarts);
    };
  if (const std::string why = switch_session(std::move(next), &journal, carry, bool(carry)); !why.empty())
    return answer(p, igtl::StatusMessage::STATUS_RESOURCE_ERROR,
                  what + ": the session at it could not be started (" + why + "); the isovalue is unchanged");
  setup_.live = live;
  setup_.hri = hri;
  client_iso_ = live.iso;
  log_.line("isovalue client " + std::to_string(p.client) + " set it: " + iso_text(live.iso) +
            " (kept for later images while inside their values)");
  answer(p, igtl::StatusMessage::STATUS_OK, what + ": done (the session restarted on the edited volume)");
}

void Server::answer_image(const PendingVolume& p, int code, const std::string& text) {
  if (code != igtl::StatusMessage::STATUS_OK) {
    n_.refused.fetch_add(1);
    log_.line("refused  client " + std::to_string(p.client) + ", IMAGE '" + p.device + "': " + text);
  }
  p.from->push(pack_status(code, p.device, text));
}

/// The bytes a session takes per voxel: its volume, the mirror, the live field's shadow, its
/// samples, an edited IMAGE's copy and bytes.
std::uint64_t Server::session_bytes_per_voxel() const {
  const std::uint64_t sample = setup_.live.format == core::SampleFormat::kFp16 ? 8 : 16;
  return 4 + 4 + 4 + sample + 8;
}

/// MessageLimits::admit_image: an IMAGE whose header alone says it does not fit the memory
/// budget is refused before its voxels arrive (they are read and dropped); one that fits is
/// counted against the budget with its session (what taking it will need) from then until
/// its Incoming is gone (converted, or refused).
AdmittedImage Server::admit_image(const std::string& device, const ImageSize& size) {
  std::lock_guard<std::mutex> image_lock(image_mu_);  // checked and counted as one step
  if (std::string why = memory_refusal(device, size, 0); !why.empty()) return {std::move(why), nullptr, 0};
  const std::uint64_t bytes = std::uint64_t(std::max(size.dims[0], 0)) * std::uint64_t(std::max(size.dims[1], 0)) *
                              std::uint64_t(std::max(size.dims[2], 0)) * (size.stored_bytes + session_bytes_per_voxel());
  images_held_bytes_.fetch_add(bytes);
  std::ostringstream s;
  s << "image    '" << device << "': " << size.dims[0] << " x " << size.dims[1] << " x " << size.dims[2]
    << " arriving, " << bytes << " bytes (as received and its session) counted against the memory budget";
  log_.line(s.str());
  return {"", std::shared_ptr<void>(nullptr, [this, bytes](void*) { images_held_bytes_.fetch_sub(bytes); }), bytes};
}

/// What taking `image` would need, against the one memory budget of every client's IMAGEs
/// (the loaders' rule: at most 3/4 of what the process may use, io::memory_budget_bytes, or
/// of --memory-mib; where that is unknown, kUnknownMemoryBytes): the image as received and
/// its new session (session_bytes_per_voxel), the running session, which serves while the
/// new one is built, and the IMAGEs in flight: an image waiting, a session being built for
/// one, and every other client's IMAGE arriving or received (`own_held_bytes`: this one's,
/// not counted twice). "" when it fits; else the STATUS, naming the sizes.
std::string Server::memory_refusal(igtl::ImageMessage& image, std::uint64_t own_held_bytes) {
  ImageSize size;
  image.GetDimensions(size.dims);
  size.stored_bytes = std::uint64_t(image.GetScalarSize()) * std::uint64_t(std::max(image.GetNumComponents(), 1));
  return memory_refusal(image.GetDeviceName(), size, own_held_bytes);
}

std::string Server::memory_refusal(const std::string& device, const ImageSize& size, std::uint64_t own_held_bytes) {
  const int* d = size.dims;
  const std::uint64_t n = std::uint64_t(std::max(d[0], 0)) * std::uint64_t(std::max(d[1], 0)) * std::uint64_t(std::max(d[2], 0));
  const std::uint64_t per_voxel = session_bytes_per_voxel();
  std::uint64_t running = 0, in_flight = 0;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    if (session_) running = session_->frame.grid.voxel_count() * per_voxel;
  }
  {
    std::lock_guard<std::mutex> lock(volume_mu_);  // a taken image moves from the one to the other under it
    if (next_volume_) in_flight += next_volume_->volume.voxels.size() * sizeof(float);
    in_flight += building_bytes_.load();
  }
  const std::uint64_t held = images_held_bytes_.load();
  in_flight += held > own_held_bytes ? held - own_held_bytes : 0;
  const std::uint64_t mine = n * (size.stored_bytes + per_voxel);
  const std::uint64_t need = mine + running + in_flight;
  std::uint64_t have = fault("budget", device) ? 0 : io::memory_budget_bytes();
  const bool unknown = have == 0;
  if (o_.memory_mib > 0) have = have == 0 ? std::uint64_t(o_.memory_mib) << 20 : std::min(have, std::uint64_t(o_.memory_mib) << 20);
  const bool by_default = have == 0;
  if (by_default) have = kUnknownMemoryBytes;
  const std::uint64_t budget = have / 4 * 3;
  if (need <= budget) return "";
  std::ostringstream s;
  s << "igtl:" << device << ": not taken: " << d[0] << " x " << d[1] << " x " << d[2] << " voxels need "
    << (need >> 20) << " MiB, more than the budget of " << (budget >> 20) << " MiB (3/4 of the " << (have >> 20)
    << " MiB of memory this server may use"
    << (by_default ? std::string(", a default: this machine's memory is unknown")
                   : unknown ? std::string(", --memory-mib: this machine's memory is unknown") : std::string())
    << "): " << (mine >> 20) << " MiB this image (as received and its session: volume, mirror, shadow, samples and an "
    << "edited copy, " << per_voxel << " bytes a voxel), " << (running >> 20) << " MiB the running session, "
    << (in_flight >> 20) << " MiB in flight (IMAGEs arriving, received or waiting from every client, and a session "
    << "being built); send it again once those are done, or a smaller one";
  return s.str();
}

/// A received volume becomes the session's: the new session is built while the old one goes
/// on serving (its edits held and settled first: the two must not use the GPU at once), then
/// the servo moves over; the force stops only for that stop and start. The sender is
/// answered once that is done ("volume taken"), or why not: the running session goes on.
void Server::swap_volume(PendingVolume p) {
  // Its voxels, then its session: in flight until it runs or is refused (counted by run()
  // from the moment it took `p`, BuildingBytes).
  const HoldEdits hold(session_mu_, preparing_);
  const std::string keep = "; the session goes on with the volume it had";
  if (!wait_edits_applied(kSettleS) || fault("settle", p.device)) {
    std::ostringstream s;
    s << "igtl:" << p.device << ": not taken: the running session's edits did not settle in " << kSettleS
      << " s (its session is never built beside them)" << keep << "; send the image again";
    return answer_image(p, igtl::StatusMessage::STATUS_BUSY, s.str());
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::unique_ptr<Session> next;
  // The image's own isovalue (as `isotouch run VOLUME` chooses it), or the one a client set.
  engine::IsoChoice choice = image_isovalue(p.volume, client_iso_);
  session::LiveFieldOptions live = setup_.live;
  servo::HriParams hri = setup_.hri;
  at_isovalue(choice.iso, p.volume.min_value, p.volume.max_value, live, hri);
  const std::uint32_t crc = o_.journal ? io::volume_crc32(p.volume) : 0;
  // The running session's volume again: its session starts afresh (the old one's edits are
  // dropped, as for any new volume), and its journal with it once the old one has stopped.
  const bool same_volume = journal_.journal && crc == journal_crc_;
  const std::string input = "igtl:" + p.device;
  io::OpenedJournal journal;
  if (!same_volume) journal = find_journal(crc);  // a journal a crash left for it: restored
  // A restored session runs at the isovalue it ran at (a client's `isovalue V` rebuilt it).
  const std::optional<core::Isosurface> restored_iso =
      journal.restore.empty() ? std::nullopt : journal.isovalue;
  // (as the client's `isovalue V` had set it, kept for later images: where it is not the one
  // this image opens at)
  const bool restored_client_iso =
      restored_iso && (restored_iso->tau != choice.iso.tau || restored_iso->inside != choice.iso.inside);
  if (restored_iso) {
    choice.iso = *restored_iso;
    choice.rule = "the isovalue its session ran at, restored with its edit journal";
    at_isovalue(choice.iso, p.volume.min_value, p.volume.max_value, live, hri);
  }
  try {
    next = prepare_session(std::move(p.volume), live, hri);
    if (!same_volume) start_journal(*next, journal, crc, input, live.iso);
  } catch (const std::exception& e) {
    return answer_image(p, igtl::StatusMessage::STATUS_RESOURCE_ERROR,
                        "igtl:" + p.device + ": not taken: a session on its " + p.dims + " voxels could not be built (" +
                            e.what() + ")" + keep);
  }
  const auto t1 = std::chrono::steady_clock::now();
  std::function<io::OpenedJournal(Session&)> reopen;
  if (same_volume)
    reopen = [this, crc, input, iso = live.iso](Session& s) {
      close_journal();  // one journal file serves one session
      return open_journal(s, crc, input, iso);
    };
  if (const std::string why = switch_session(std::move(next), &journal, reopen); !why.empty())
    return answer_image(p, igtl::StatusMessage::STATUS_RESOURCE_ERROR,
                        "igtl:" + p.device + ": not taken: a session on its " + p.dims + " voxels could not be started (" +
                            why + ")" + keep);
  setup_.live = live;
  setup_.hri = hri;
  journal_crc_ = crc;
  if (restored_client_iso) client_iso_ = restored_iso;
  const auto t2 = std::chrono::steady_clock::now();
  n_.images.fetch_add(1);
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << "volume   client " << p.client << ", '" << p.device << "': " << p.dims
    << " taken, now the session's volume (tool kept; built in "
    << std::chrono::duration<double, std::milli>(t1 - t0).count() << " ms while the old one served, servo off for "
    << std::chrono::duration<double, std::milli>(t2 - t1).count() << " ms); " << engine::iso_line(choice);
  log_.line(s.str());
  answer_image(p, igtl::StatusMessage::STATUS_OK, "volume taken: " + p.dims + "; " + engine::iso_line(choice));
}

/// The edit journal of a session on a volume of CRC `volume_crc32` (the scene's, or an
/// IMAGE's: io/journal_offer.h): a journal a killed serve left for that volume is restored
/// into `s` (before its live session starts) or not, as --restore says; the journal then
/// starts afresh with what was restored, and `s` appends to it. `input` names the volume in
/// the journal's header. The log says what was done. Returned for the caller to own (off:
/// a null journal).
io::OpenedJournal Server::open_journal(Session& s, std::uint32_t volume_crc32, const std::string& input,
                                        const core::Isosurface& iso) {
  io::OpenedJournal j = find_journal(volume_crc32);
  start_journal(s, j, volume_crc32, input, iso);
  return j;
}

/// The first half of open_journal(): the journal of the volume of CRC `volume_crc32` opened
/// (locked), and what a killed serve left in it taken or not, as --restore says (the log says
/// which). A restored journal's isovalue (OpenedJournal::isovalue) is the one its session
/// must be built at. Off: a null journal.
io::OpenedJournal Server::find_journal(std::uint32_t volume_crc32) {
  if (!o_.journal) return {};
  std::ostringstream said;
  std::istringstream no_terminal;
  io::OpenedJournal j = io::open_journal("serve", volume_crc32, o_.restore ? io::RestoreChoice::kYes : io::RestoreChoice::kNo,
                                         said, no_terminal, false);
  std::istringstream lines(said.str());
  for (std::string l; std::getline(lines, l);) log_.line(l);
  if (j.restore.empty()) j.isovalue.reset(), j.history_restarts.clear();  // a new session: the volume's own
  return j;
}

/// The second half: `j`'s restored edits applied to `s` (built at `iso`: j.isovalue where it
/// has one; the undo history dropped where the journaled session was rebuilt), then the
/// journal started afresh with them, `iso` and the restarts, and `s` appending to it.
void Server::start_journal(Session& s, io::OpenedJournal& j, std::uint32_t volume_crc32, const std::string& input,
                           const core::Isosurface& iso) {
  if (!j.journal) return;
  j.isovalue = iso;
  io::apply_restored(s.parts->edits(), j.restore, &s.parts->buffer(), j.history_restarts);
  if (!j.restore.empty()) {  // the mirror (saves, IMAGEs sent) starts as the restored volume, all of it new
    s.mirror = std::make_shared<EditMirror>(s.parts->edits().volume());
    VoxelBox all;
    all.hi = s.frame.grid.dims;
    s.mirror->restore_changed(all);
    log_.line("journal  restored " + std::to_string(j.restore.size()) + " edits at " + iso_text(iso) +
              " (the session's at the crash)");
  }
  io::Recording header;
  header.scene_path = input;
  header.rate_hz = scene_.hri.rate_hz;
  header.volume_crc32 = volume_crc32;
  header.isovalue = j.isovalue;
  header.history_restarts = j.history_restarts;
  j.journal->start(header, j.restore);
  s.journal = j.journal.get();
  log_.line("journal  " + j.journal->path() + " (this session's edits, kept through a crash)");
}

/// A journal that cannot go on past a change: the file holds the session before it, and is
/// moved aside (PATH.before-change, replacing an older one) before its lock goes, so that it
/// is never offered as the session that ran; the log says why.
void Server::set_journal_aside(std::unique_ptr<io::Journal>& journal, const std::string& why) {
  const std::string path = journal->path(), aside = path + ".before-change";
  std::error_code ec;
  std::filesystem::rename(path, aside, ec);
  journal.reset();
  log_.line("journal  " + why + "; the session goes on without its journal (" +
            (ec ? "the file could not be moved aside: " + ec.message() : "the file moved aside to " + aside) + ")");
}

/// `from` (the journal of the session just stopped, on the volume journal_crc_) goes on for
/// `s`, the session rebuilt on its edited volume at `iso` (`isovalue V`): the same file
/// started afresh with every edit it holds, `iso` and `restarts` in its header (a restart
/// of std::size_t(-1): at the edits it holds; the undo history started afresh there), and
/// `s` appending to it. A restore then rebuilds the same session: the volume, the edits,
/// the isovalue. Until the new file replaces the old one, the old one holds the session
/// before the change, locked throughout (Journal::restart). When it cannot go on, the log
/// says why, the old file is moved aside (PATH.before-change: never offered as this
/// session's) and `s` runs without one.
io::OpenedJournal Server::carry_journal(io::OpenedJournal& from, Session& s, const std::optional<core::Isosurface>& iso,
                                        const std::vector<std::size_t>& restarts) {
  io::OpenedJournal j;
  if (!from.journal) return j;
  const std::string path = from.journal->path();
  std::optional<io::JournalLeft> held;
  try {
    from.journal->flush();  // throws when an earlier write failed (a full disk): the file is behind
    held = from.journal->left(journal_crc_);
  } catch (const std::exception& e) {
    set_journal_aside(from.journal, e.what());
    return j;
  }
  std::vector<session::EditEvent> edits = held ? std::move(held->edits) : std::vector<session::EditEvent>{};
  j.history_restarts = restarts;
  for (std::size_t& r : j.history_restarts) r = std::min(r, edits.size());
  j.isovalue = iso;
  io::Recording header;
  header.scene_path = held ? held->input : std::string();
  header.rate_hz = scene_.hri.rate_hz;
  header.volume_crc32 = journal_crc_;
  header.isovalue = j.isovalue;
  header.history_restarts = j.history_restarts;
  try {
    from.journal->restart(header, edits);  // its lock held throughout
  } catch (const std::exception& e) {
    set_journal_aside(from.journal, e.what());
    return {};
  }
  j.journal = std::move(from.journal);
  s.journal = j.journal.get();
  log_.line("journal  " + path + " goes on" + (iso ? " at " + iso_text(*iso) : std::string()) + " (" +
            std::to_string(edits.size()) + " edits kept, the undo history restarts after them)");
  return j;
}

/// The running session ended (serve stops, or an IMAGE or an isovalue replaced it): its
/// journal is deleted.
void Server::close_journal() {
  if (!journal_.journal) return;
  try {
    journal_.journal->close();
    log_.line("journal  closed: the session's edits are no longer kept (" + std::to_string(journal_.journal->edits()) +
              " edits; the session ended)");
  } catch (const std::exception& e) {
    log_.line(std::string("journal  ") + e.what());
  }
  journal_.journal.reset();
}

/// Stops the running session's servo and edits and counts its figures; returns the stopped
/// session (nullptr when none ran), which start_session() can run again (its journal stays
/// open until the caller knows it ended: close_journal()).
std::unique_ptr<Session> Server::stop_session() {
  std::unique_ptr<Session> s;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    s = std::move(session_);
  }
  if (!s) return s;
  // Abandoned in the renderer: the process ends there (the session and device_ outlive
  // the stuck thread).
  session::stop_or_end_process(s->live(), "isotouch serve");
  const session::LiveStats st = s->live().stats();
  ticks_ += st.ticks;
  faults_ += st.faults;
  missed_ += st.missed_deadlines;
  input_waits_ += s->live().servo_thread()->input_waits();
  input_wait_timeouts_ += s->live().servo_thread()->input_wait_timeouts();
  const servo::DeviceCounters dc = s->live().servo_thread()->device_counters();
  stale_ += dc.stale;  // zero force on each
  disconnected_ += dc.disconnected;
  device_faults_ += dc.fault;
  uncalibrated_ += dc.uncalibrated;
  refused_reports_ += dc.refused;
  return s;
}

/// The servo moves from the running session to `next`. When `next` cannot be started
/// (a thread, memory, the device), the old session is started again on its own volume and
/// edits, and the reason is returned for the sender's STATUS ("" when `next` runs). Only
/// when the old one cannot be started either does the exception end the server.
/// `journal_after_stop` (the same volume again: one journal file serves one session; an
/// isovalue: the session goes on) closes the running journal or carries it on, and gives the
/// new session's, once the old session has stopped appending to it. `carried`: it carried it
/// on (carry_journal), so when `next` cannot start, the old session gets it back as it was.
std::string Server::switch_session(std::unique_ptr<Session> next, io::OpenedJournal* next_journal,
                                   const std::function<io::OpenedJournal(Session&)>& journal_after_stop, bool carried) {
  std::unique_ptr<Session> old = stop_session();
  const std::optional<core::Isosurface> old_iso = journal_.isovalue;
  const std::vector<std::size_t> old_restarts = journal_.history_restarts;
  try {
    if (journal_after_stop && next_journal) *next_journal = journal_after_stop(*next);  // closes journal_, or carries it on
    start_session(std::move(next));
    if (old && old->journal && old->journal == journal_.journal.get()) close_journal();  // the old session ended
    if (next_journal) journal_ = std::move(*next_journal);
    return "";
  } catch (const std::exception& e) {
    const std::string why = e.what();
    log_.line("session  the new session could not be started (" + why + "); the old one goes on");
    if (!old) throw;
    if (old->journal && old->journal != journal_.journal.get()) {  // closed for the new session: not appended to
      old->journal = nullptr;
      if (carried && next_journal && next_journal->journal) {  // the same file again, as it was before the change
        journal_ = carry_journal(*next_journal, *old, old_iso, old_restarts);
      }
      if (!old->journal) log_.line("journal  the old session goes on without its journal (it was closed for the new one)");
    }
    old->parts->detach();
    start_session(std::move(old));
    return why;
  }
}

void Server::join_threads(std::thread& display, std::thread& commands) noexcept {
  stop_ = true;
  if (acceptor_.joinable()) acceptor_.join();  // clients_ is this thread's alone from here
  if (display.joinable()) display.join();
  if (commands.joinable()) commands.join();
  {
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (Client& c : clients_) c.conn->shutdown();
  }
  for (Client& c : clients_) {
    if (c.thread.joinable()) c.thread.join();
    if (c.outbox) c.outbox->close();
  }
}

/// --haptic: the factory's device, as `isotouch run --live` opens it (no scripted hand:
/// `sim` is refused; `null` holds the HIP at the volume's centre).
void Server::open_haptic() {
  run::DeviceSetup ds = run::device_setup(scene_, setup_);
  ds.script = nullptr;
  ds.start_world_m = setup_.volume.grid.centre_m();
  haptic_ = std::make_unique<run::HapticDevice>(run::open_haptic_device(o_.haptic, ds, o_.sched_fifo ? 70 : 0));
  echo_device_ = std::make_unique<EchoDevice>(*haptic_->io);
  log_.line("device   " + haptic_->description);
}

int Server::run() {
  std::ostringstream setup_log;
  setup_ = run::setup_scene(scene_, o_.run, setup_log);
  if (!o_.haptic.empty()) open_haptic();
  if (!haptic_) device_.set_registration(o_.registration);
  const std::string device =
      haptic_ ? "device --haptic " + o_.haptic
              : "stream '" + o_.stream + "'" +
                    (o_.registration.is_identity() ? std::string() : " registered (" + o_.registration.describe() + ")") +
                    " + offset " + mm3(o_.offset_mm) + " mm (RAS)";
  log_.line("serve    listening on " + o_.host + ":" + std::to_string(listener_.port()) + ", " + device + ", display " +
            std::to_string(int(o_.display_hz)) + " Hz, servo " + std::to_string(int(scene_.hri.rate_hz)) + " Hz, " +
            iso_text(setup_.live.iso) + " (the scene's)");
  {
    journal_crc_ = io::volume_crc32(setup_.volume);
    io::OpenedJournal j = find_journal(journal_crc_);
    if (j.isovalue && (j.isovalue->tau != setup_.live.iso.tau || j.isovalue->inside != setup_.live.iso.inside)) {
      // a restored session runs at the isovalue a client set (`isovalue V` rebuilt it)
      at_isovalue(*j.isovalue, setup_.volume.min_value, setup_.volume.max_value, setup_.live, setup_.hri);
      client_iso_ = j.isovalue;
      log_.line("journal  the restored session runs at " + iso_text(*j.isovalue) + ", a client's (not the scene's)");
    }
    std::unique_ptr<Session> first = prepare_session(setup_.volume, setup_.live, setup_.hri);
    if (setup_.cut) first->parts->edits().sculptor().set_material_cut(setup_.cut);  // the scene's materials
    start_journal(*first, j, journal_crc_, std::filesystem::absolute(scene_.file).string(), setup_.live.iso);
    journal_ = std::move(j);
    start_session(std::move(first));
  }
  session::install_stop_handlers();
  if (o_.on_listening) o_.on_listening(listener_.port());
  tool_ = scene_.edits.brush;
  acceptor_ = std::thread([this] {
    while (!stop_) {
      try {
        accept_clients();
      } catch (const std::exception& e) {  // e.g. no thread for a client: it is not taken, the server goes on
        try {
          log_.line(std::string("client   a connection not taken: ") + e.what());
        } catch (...) {
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
      }
    }
  });
  std::thread display([this] { display_loop(); });
  std::thread commands([this] { command_loop(); });
  std::thread replies;
  if (o_.reply_force) replies = std::thread([this] { replies_.run(stop_); });
  struct Join {
    std::thread& t;
    ~Join() {
      if (t.joinable()) t.join();
    }
  } join_replies{replies};  // after the joiner below has set stop_
  // Every way out of run() (an exception from start_session or stop_session too) stops and
  // joins the display, command and client threads first: a joinable std::thread destroyed is std::terminate.
  const ThreadsJoiner joiner(*this, display, commands);
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  while (session::stop_signal() == 0 && (o_.seconds <= 0 || elapsed() < o_.seconds)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // connections: the accept thread
    std::optional<PendingVolume> v;
    std::optional<Pending> iso;
    std::optional<PendingLabels> labels;
    // A taken IMAGE's voxels and session count against the memory budget from the moment it
    // stops being next_volume_ (under the same lock) until it runs or is refused: between the
    // two it counted nowhere, and a second IMAGE could pass beside it.
    std::optional<BuildingBytes> building;
    {
      std::lock_guard<std::mutex> lock(volume_mu_);
      v.swap(next_volume_);
      if (v) building.emplace(building_bytes_, v->volume.grid.voxel_count() * session_bytes_per_voxel());
      if (!v) iso.swap(next_iso_);
      if (!v && !iso) labels.swap(next_labels_);
      changing_ = v || iso;
    }
    struct Changed {
      Server& s;
      ~Changed() {
        std::lock_guard<std::mutex> lock(s.volume_mu_);
        s.changing_ = false;
      }
    } changed{*this};
    if (v && fault("taken", v->device)) {  // the test seam: the taken IMAGE held 5 s before its build
      log_.line("test     '" + v->device + "' taken, held 5 s before its session is built (ISOTOUCH_SERVE_TEST_FAULT)");
      std::this_thread::sleep_for(std::chrono::seconds(5));
    }
    if (v) swap_volume(std::move(*v));
    if (iso) restart_at_isovalue(*iso);
    if (labels) apply_labels(std::move(*labels));
  }
  join_threads(display, commands);
  if (const std::unique_ptr<Session> last = stop_session(); last && last->journal) close_journal();
  std::ostringstream s;
  s << "served   " << n_.clients << " clients; images taken " << n_.images << ", label maps taken " << n_.label_maps << ", refused " << n_.refused
    << " messages, transforms " << n_.transforms << " (" << device_.pushed() << " on '" << o_.stream << "'), strings "
    << n_.strings << ", skipped " << n_.skipped << ", broken streams " << n_.broken << "; sent " << n_.sent
    << " transforms (" << n_.dropped_sends << " dropped: a client not reading, " << n_.busy_sends
    << " skipped: another send to that client under way), " << n_.images_sent << " edited images; " << n_.idle
    << " quiet clients closed for a new connection, " << n_.dropped_clients << " dropped not reading; " << n_.commands << " commands; " << sessions_ << " sessions, "
    << ticks_ << " servo ticks (" << missed_ << " missed deadlines), " << stale_ << " stale (no fresh "
    << (haptic_ ? "reading" : "TRANSFORM") << ": zero force), " << faults_ << " faults";
  log_.line(s.str());
  const bool device_lost = disconnected_ + device_faults_ + refused_reports_ > 0;
  if (haptic_)
    log_.line("device   " + haptic_->description + ": disconnected " + std::to_string(disconnected_) + ", fault " +
              std::to_string(device_faults_) + ", refused " + std::to_string(refused_reports_) +
              ", waiting for calibration " + std::to_string(uncalibrated_) + " ticks (zero force on each)");
  if (session::stop_signal() != 0) return exit_code::signalled(session::stop_signal());
  if (faults_ > 0) return exit_code::kServoFaults;
  if (device_lost) return exit_code::kDeviceLost;
  return save_failed_ ? exit_code::kSaveFailed : exit_code::kOk;
}

}  // namespace

int serve(const io::Scene& scene, const ServeOptions& options, std::ostream& log, ServeStats& stats) {
  Server s(scene, options, log);
  const int rc = s.run();
  stats = s.stats();
  return rc;
}

int serve(const io::Scene& scene, const ServeOptions& options, std::ostream& log) {
  ServeStats ignored;
  return serve(scene, options, log, ignored);
}

}  // namespace isotouch::service
