#include "isotouch/service/serve.h"

#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <list>
#include <memory>
#include <mutex>
#include <optional>
#include <ostream>
#include <sstream>
#include <thread>

#include <igtlStatusMessage.h>

#include "isotouch/session/edit_session.h"
#include "isotouch/core/exit_codes.h"
#include "isotouch/servo/hri.h"
#include "isotouch/service/igtl_socket.h"
#include "isotouch/service/image_volume.h"
#include "isotouch/session/live_session.h"
#include "isotouch/run/scene_setup.h"
#include "isotouch/session/stop_signal.h"
#include "isotouch/service/transform_device.h"
#include "isotouch/servo/triple_buffer.h"

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
  std::atomic<long> sent{0}, dropped_sends{0};
};

struct Client {
  std::unique_ptr<Connection> conn;
  std::thread thread;
  std::atomic<bool> done{false};
  int id = 0;
};

/// One session on one volume: the edits, the buffer the servo reads, the renderer, the
/// live session around them.
struct Session {
  std::unique_ptr<session::EditSession> edits;
  servo::TripleBuffer<core::SampleField> buffer;
  std::unique_ptr<servo::HriRenderer> hri;
  std::unique_ptr<session::LiveSession> live;
  engine::Volume frame;  // the volume's grid and direction (voxels dropped)
};

class Server {
 public:
  Server(const io::Scene& scene, const ServeOptions& o, std::ostream& out)
      : scene_(scene), o_(o), log_(out), listener_(o.host, o.port) {}

  int run();

 private:
  void client_loop(Client& c);
  void read_messages(Client& c);
  void refuse_connection(int fd);
  void handle(Client& c, Incoming& in);
  void refuse(Client& c, const Incoming& in, int code, const std::string& why);
  void display_loop();
  void start_session(engine::Volume v);
  void stop_session();
  void accept_clients();
  /// Sets stop_, joins `display` and every client thread (after shutting their
  /// connections); idempotent.
  void join_threads(std::thread& display) noexcept;
  struct ThreadsJoiner {
    Server& server;
    std::thread& display;
    ~ThreadsJoiner() { server.join_threads(display); }
  };

  const io::Scene& scene_;
  ServeOptions o_;
  Log log_;
  Listener listener_;
  run::SceneSetup setup_;
  TransformDevice device_;
  Counters n_;
  std::atomic<bool> stop_{false};
  std::mutex clients_mu_;
  std::list<Client> clients_;
  int next_id_ = 1;
  std::mutex session_mu_;  // guards session_ (swapped by the main thread, read by the display thread)
  std::unique_ptr<Session> session_;
  long sessions_ = 0, ticks_ = 0, faults_ = 0, stale_ = 0;
  std::mutex volume_mu_;
  std::optional<engine::Volume> next_volume_;  // a received IMAGE waiting for the main thread
};

std::string mm3(const core::Vec3& v) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(1) << "(" << v.x << ", " << v.y << ", " << v.z << ")";
  return s.str();
}

void Server::refuse(Client& c, const Incoming& in, int code, const std::string& why) {
  n_.refused.fetch_add(1);
  log_.line("refused  client " + std::to_string(c.id) + ", " + in.type + " '" + in.device + "': " + why);
  c.conn->send(pack_status(code, in.device, why));
}

void Server::handle(Client& c, Incoming& in) {
  using K = Incoming::Kind;
  switch (in.kind) {
    case K::kImage:
      try {
        engine::Volume v = volume_from_image(*in.image);
        const std::string dims = std::to_string(v.grid.dims[0]) + " x " + std::to_string(v.grid.dims[1]) + " x " +
                                 std::to_string(v.grid.dims[2]);
        {
          std::lock_guard<std::mutex> lock(volume_mu_);
          next_volume_ = std::move(v);
        }
        n_.images.fetch_add(1);
        log_.line("image    client " + std::to_string(c.id) + ", '" + in.device + "': " + dims + " taken");
        c.conn->send(pack_status(igtl::StatusMessage::STATUS_OK, in.device, "volume taken: " + dims));
      } catch (const std::exception& e) {
        refuse(c, in, igtl::StatusMessage::STATUS_CONFIG_ERROR, e.what());
      }
      break;
    case K::kTransform:
      n_.transforms.fetch_add(1);
      if (in.device == o_.stream) {
        const double t[3] = {in.matrix[0][3], in.matrix[1][3], in.matrix[2][3]};
        device_.push_mm(t);
      }
      break;
    case K::kString:
      n_.strings.fetch_add(1);
      refuse(c, in, igtl::StatusMessage::STATUS_UNKNOWN_INSTRUCTION, "STRING commands are not supported yet");
      break;
    case K::kSkipped: n_.skipped.fetch_add(1); break;
    case K::kRefused:
      refuse(c, in, in.why.find("CRC") != std::string::npos ? igtl::StatusMessage::STATUS_CHECKSUM_ERROR
                                                             : igtl::StatusMessage::STATUS_CONFIG_ERROR, in.why);
      break;
    default: break;
  }
}

void Server::client_loop(Client& c) {
  try {
    read_messages(c);
  } catch (const std::exception& e) {  // e.g. bad_alloc: this client is dropped, the server goes on
    log_.line("client   " + std::to_string(c.id) + " dropped: " + e.what());
  } catch (...) {
    log_.line("client   " + std::to_string(c.id) + " dropped: an unknown exception");
  }
  log_.line("client   " + std::to_string(c.id) + " gone");
  c.conn->shutdown();
  c.done = true;
}

void Server::read_messages(Client& c) {
  for (;;) {
    Incoming in = read_message(*c.conn, o_.limits);
    if (in.kind == Incoming::Kind::kClosed) break;
    if (in.kind == Incoming::Kind::kBroken) {
      n_.broken.fetch_add(1);
      refuse(c, in, igtl::StatusMessage::STATUS_CONFIG_ERROR, in.why + "; closing the connection");
      break;
    }
    handle(c, in);
  }
}

void Server::accept_clients() {
  const int fd = listener_.accept(50);
  std::lock_guard<std::mutex> lock(clients_mu_);
  for (auto it = clients_.begin(); it != clients_.end();) {  // reap the finished
    if (it->done) {
      it->thread.join();
      it = clients_.erase(it);
    } else {
      ++it;
    }
  }
  if (fd < 0) return;
  if (int(clients_.size()) >= o_.max_clients) return refuse_connection(fd);
  Client& c = clients_.emplace_back();
  c.id = next_id_++;
  c.conn = std::make_unique<Connection>(fd, o_.receive_timeout_ms, o_.message_timeout_ms, &stop_);
  n_.clients.fetch_add(1);
  log_.line("client   " + std::to_string(c.id) + " connected");
  c.thread = std::thread([this, &c] { client_loop(c); });
}

/// One connection past max_clients: a STATUS saying so (never waited for), then closed.
void Server::refuse_connection(int fd) {
  Connection extra(fd, o_.receive_timeout_ms, o_.message_timeout_ms, &stop_);
  const std::string why = "the server has its " + std::to_string(o_.max_clients) + " clients; connection refused";
  extra.send_droppable(pack_status(igtl::StatusMessage::STATUS_NOT_READY, "", why));
  n_.refused.fetch_add(1);
  log_.line("refused  a connection: " + why);
}

void Server::display_loop() {
  const auto period = std::chrono::duration<double>(1.0 / o_.display_hz);
  auto next = std::chrono::steady_clock::now();
  const double stall_s = std::max(0.05, 4.0 / scene_.hri.rate_hz);
  while (!stop_) {
    next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
    std::this_thread::sleep_until(next);
    std::vector<std::uint8_t> out;
    {
      std::lock_guard<std::mutex> lock(session_mu_);
      if (!session_) continue;
      const session::Observed ob = session_->live->observe();
      if (ob.tick < 0) continue;
      const core::Vec3 hip = device_.grid_to_ras_mm(ob.hip_m), vhip = device_.grid_to_ras_mm(ob.vhip_m);
      const core::Vec3 f = device_.force_ras_n(stall_s);
      for (const auto& [name, v] : {std::pair{"HIP", hip}, std::pair{"Proxy", vhip}, std::pair{"Force", f}}) {
        const double t[3] = {v.x, v.y, v.z};
        const auto b = pack_translation(name, t);
        out.insert(out.end(), b.begin(), b.end());
      }
    }
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (Client& c : clients_) {
      if (c.done || !c.conn->alive()) continue;
      if (c.conn->send_droppable(out)) n_.sent.fetch_add(3);
      else n_.dropped_sends.fetch_add(3);
    }
  }
}

void Server::start_session(engine::Volume v) {
  auto s = std::make_unique<Session>();
  s->edits = std::make_unique<session::EditSession>(v, setup_.vk.get(), setup_.live, scene_.edits.history_limit_mib);
  s->buffer.publish(s->edits->current());
  s->hri = std::make_unique<servo::HriRenderer>(setup_.hri);
  s->frame.grid = v.grid;
  s->frame.direction = v.direction;
  device_.set_frame(v, o_.offset_mm);  // no servo runs now
  session::LiveSessionConfig c;
  c.servo.rate_hz = scene_.hri.rate_hz;
  c.servo.sched_fifo = c.servo.pin_cpu = c.servo.lock_memory = o_.sched_fifo;
  c.servo.stale_timeout_s = o_.stale_s;
  s->live = std::make_unique<session::LiveSession>(*s->edits, s->buffer, *s->hri, device_, c);
  if (const std::string note = s->live->start(); !note.empty()) log_.line("servo    " + note);
  ++sessions_;
  std::lock_guard<std::mutex> lock(session_mu_);
  session_ = std::move(s);
}

void Server::stop_session() {
  std::unique_ptr<Session> s;
  {
    std::lock_guard<std::mutex> lock(session_mu_);
    s = std::move(session_);
  }
  if (!s) return;
  // Abandoned in the renderer: the process ends there (the session and device_ outlive
  // the stuck thread).
  session::stop_or_end_process(*s->live, "isotouch serve");
  const session::LiveStats st = s->live->stats();
  ticks_ += st.ticks;
  faults_ += st.faults;
  stale_ += s->live->servo_thread()->device_counters().stale;  // zero force on each
}

void Server::join_threads(std::thread& display) noexcept {
  stop_ = true;
  if (display.joinable()) display.join();
  {
    std::lock_guard<std::mutex> lock(clients_mu_);
    for (Client& c : clients_) c.conn->shutdown();
  }
  for (Client& c : clients_)
    if (c.thread.joinable()) c.thread.join();
}

int Server::run() {
  std::ostringstream setup_log;
  setup_ = run::setup_scene(scene_, o_.run, setup_log);
  log_.line("serve    listening on " + o_.host + ":" + std::to_string(listener_.port()) + ", stream '" + o_.stream +
            "' + offset " + mm3(o_.offset_mm) + " mm (RAS), display " + std::to_string(int(o_.display_hz)) +
            " Hz, servo " + std::to_string(int(scene_.hri.rate_hz)) + " Hz");
  start_session(setup_.volume);
  session::install_stop_handlers();
  std::thread display([this] { display_loop(); });
  // Every way out of run() (an exception from start_session or stop_session too) stops and
  // joins the display and client threads first: a joinable std::thread destroyed is std::terminate.
  const ThreadsJoiner joiner(*this, display);
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  while (session::stop_signal() == 0 && (o_.seconds <= 0 || elapsed() < o_.seconds)) {
    accept_clients();
    std::optional<engine::Volume> v;
    {
      std::lock_guard<std::mutex> lock(volume_mu_);
      v.swap(next_volume_);
    }
    if (v) {
      stop_session();
      start_session(std::move(*v));
      log_.line("volume   now the session's volume (isovalue and tool kept)");
    }
  }
  join_threads(display);
  stop_session();
  std::ostringstream s;
  s << "served   " << n_.clients << " clients; images taken " << n_.images << ", refused " << n_.refused
    << " messages, transforms " << n_.transforms << " (" << device_.pushed() << " on '" << o_.stream << "'), strings "
    << n_.strings << ", skipped " << n_.skipped << ", broken streams " << n_.broken << "; sent " << n_.sent
    << " transforms (" << n_.dropped_sends << " dropped: a client not reading); " << sessions_ << " sessions, "
    << ticks_ << " servo ticks, " << stale_ << " stale (no fresh TRANSFORM: zero force), " << faults_ << " faults";
  log_.line(s.str());
  if (session::stop_signal() != 0) return exit_code::signalled(session::stop_signal());
  return faults_ > 0 ? exit_code::kServoFaults : exit_code::kOk;
}

}  // namespace

int serve(const io::Scene& scene, const ServeOptions& options, std::ostream& log) {
  Server s(scene, options, log);
  return s.run();
}

}  // namespace isotouch::service
