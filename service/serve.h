// serve.h - `isotouch serve`: an OpenIGTLink server (3D Slicer's OpenIGTLinkIF, PLUS, the
// OpenIGTLink examples) hosting one live session (session/live_session.h).
//
//   client threads (one per connection): read_message ->
//     IMAGE (3-D, scalar)          -> volume_from_image -> the main thread swaps the session's volume
//     TRANSFORM named `stream`     -> TransformDevice (the servo's device; stale: zero force;
//                                     one client's: the first, until it stops for stale_s or goes),
//                                     unless `haptic` names the device (then ignored)
//     STRING                       -> parse_command (commands.h) -> the command thread
//     LBMETA                       -> the images it names are label maps: such an IMAGE (on the
//                                     session volume's grid, every value named) becomes the
//                                     session's materials (label_map.h), the drill's cut per material
//     anything refused             -> a STATUS back naming why; the connection goes on when it can
//   display thread: every 1 / display_hz, to every client: TRANSFORMs "HIP" and "Proxy"
//     (translation in mm, RAS; only while the servo renders a fresh pose) and "Force"
//     (translation = force in N, RAS; PLUS's convention)
//   command thread: every 1 / display_hz, runs the commands in the order they came (a
//     STATUS back for each), submits the tool's brush at the proxy while applying and in
//     contact, and at most image_hz times a second sends the edited voxels as an IMAGE to
//     the clients that sent an IMAGE or a command (edit_mirror.h)
//   haptic device (`haptic`, the `--haptic` factory's: openhaptics, forcedimension, igtl, emu,
//     hid, ...): its own threads hand the servo the pose and take the force, through the
//     servo's safety gate and the device's stall rule, as in `isotouch run --live`
//   accept thread: accepts connections throughout (also while a volume's session is built),
//     frees the slots of the clients gone (closed, dropped, or quiet and closed to give a new
//     connection their slot)
//   each client's Outbox thread (outbox.h): sends it the STATUS answers and edited IMAGEs, so
//     no other thread waits for a peer; a client that does not take them is dropped
//   main thread: starts and swaps the session (a new volume, a new isovalue), stops on a
//     signal or after `seconds`.
// Part of isotouch::serve.
#pragma once
#include <array>
#include <functional>
#include <iosfwd>
#include <memory>
#include <string>

#include "isotouch/service/igtl_message.h"
#include "isotouch/service/registration.h"
#include "isotouch/run/run_scene.h"
#include "isotouch/io/scene.h"
#include "isotouch/core/vec3.h"

namespace isotouch::service {

struct ServeOptions {
  std::string host = "127.0.0.1";     ///< address to listen on ("0.0.0.0": every interface; no authentication)
  int port = 18944;                   ///< 0: any free port (printed)
  std::string stream = "StylusToTracker";  ///< device name of the TRANSFORMs that move the HIP
  /// The haptic device, a `--haptic KIND:ARGS` spec (run/haptic_device.h; not `sim`, which
  /// needs a scripted hand); "": the TRANSFORM stream is the device. With one, the HIP is the
  /// device's, mapped as `isotouch run` maps it (grid [m] = scene's workspace_scale * device
  /// [m] + the session volume's centre), its stale timeout is the device's own, the servo's
  /// force goes to it, and TRANSFORMs named `stream` move nothing; an `igtl:` device's rate
  /// is measured and the scene's stiffness checked against it (Scene::allow_unstable_stiffness).
  std::string haptic;
  core::Vec3 offset_mm;               ///< added to the stream's translation [mm, RAS], after `registration`
  /// The tracker's rigid registration to the image (registration.h): the stream's poses
  /// [mm, tracker RAS] -> image RAS (R p + t), the Force replies (`reply_force`) back with
  /// R^T. Identity: the stream is in the image's frame. Not with `haptic`.
  Registration registration;
  /// A TRANSFORM under this name from any client replaces `registration` (PLUS's
  /// TrackerToImage); answered with a STATUS (taken, or refused when not rigid). "": none.
  std::string registration_name = "TrackerToImage";
  double display_hz = 60;             ///< HIP / proxy / force TRANSFORMs sent per second
  double stale_s = 0.1;               ///< no TRANSFORM for this long: stale, zero force [s] (not with `haptic`)
  int receive_timeout_ms = 2000;      ///< longest silence inside a message before the client is dropped
  int message_timeout_ms = 60000;     ///< longest a whole message may take from its first byte [ms]
  int max_clients = 8;                ///< more connected at once: refused with a STATUS
  /// With every slot taken, a new connection gets the slot of the client quiet longest, if it
  /// has sent no byte for at least this long [s] (0: never) and is not a session's client (it
  /// sent an IMAGE or a command). A quiet client (a viewer that only reads the TRANSFORMs) keeps
  /// its connection until the slots are full and a new one comes.
  double idle_timeout_s = 60;
  double seconds = 0;                 ///< stop after this long (0: on SIGINT / SIGTERM only)
  std::string save_dir = ".";         ///< the folder `save NAME` writes into
  /// The edit journal (io/journal.h) of the session on the scene's volume:
  /// $XDG_STATE_HOME/isotouch/serve-CRC.journal (CRC: the volume's as read), every applied
  /// edit written at once, deleted when that session ends (serve stops, or an IMAGE or an
  /// isovalue replaces it); a kill leaves it. False: none.
  bool journal = true;
  /// A journal a killed serve left on this volume: restored before the session starts
  /// (true), or kept aside as JOURNAL.unrestored (false). The log says which.
  bool restore = true;
  double image_hz = 2;                ///< edited-volume IMAGEs sent per second at most (0: none)
  bool image_whole = false;           ///< send the whole image, not the changed sub-volume
  /// Answer each TRANSFORM of the stream with a TRANSFORM "Force" (translation = force in N,
  /// RAS) to the client that sent it, as soon as the servo has rendered that pose (lock-step,
  /// as a PLUS device loop), its header stamp the pose's; never waited for (a client that
  /// does not read loses them).
  bool reply_force = false;  ///< not with `haptic`
  std::function<void(int port)> on_listening;  ///< called once listening (benches, tests)
  bool sched_fifo = false;            ///< ask for SCHED_FIFO and pinning for the servo
  /// The memory the server may use [MiB] (0: io::memory_budget_bytes, the machine's and its
  /// limits', or 4096 MiB where that is unknown; else the smaller of the two): an IMAGE whose
  /// session, with the running one's and every client's IMAGEs in flight, would pass 3/4 of
  /// it is refused with a STATUS naming the need, the budget and the part in flight.
  double memory_mib = 0;
  /// Tests only: asked at each spot where the server can fail for a cause a CPU Vulkan driver
  /// does not produce ("prepare": the new session's build throws std::bad_alloc; "settle":
  /// the running session's edits did not settle; "edited": packing the edited IMAGE throws
  /// std::bad_alloc), with the image's device name ("link": a stream's link simulation,
  /// check_stream_rate's, throws std::bad_alloc, with "DEVICE@HZ": its stream's device name
  /// and its rate bucket's rate [Hz], rounded); true: fail there. Empty: never.
  std::function<bool(const std::string& where, const std::string& image)> fault_for_test;
  MessageLimits limits;
  run::RunOptions run;                ///< the Vulkan device (scene setup)
};

/// Serves `scene` (its volume first, its isovalue, passes and HRI parameters throughout).
/// Prints "serve    listening on HOST:PORT" once listening, a line per client, volume and
/// refusal, and the counters at the end.
/// @return 0; 4 when servo ticks were faults; 5 when the `haptic` device was disconnected,
/// faulty or sent refused reports (the server went on serving); 6 when a save command could
/// not write (the session went on); 128 + the signal when a signal stopped it.
/// @throws std::runtime_error if the port cannot be opened; as setup_scene; as
/// run::open_haptic_device (std::invalid_argument also for `haptic` with `reply_force`).
int serve(const io::Scene& scene, const ServeOptions& options, std::ostream& log);

/// What a serve() did, for a caller that measures it (`isotouch bench serve`).
struct ServeStats {
  long ticks = 0, missed_deadlines = 0, faults = 0, stale = 0, sessions = 0, images = 0;
  long replies = 0;        ///< Force replies sent (reply_force)
  long stall_replies = 0;  ///< of those: a pose the servo did not render within 2 ms (no session running: zero)
  /// The rendered replies' time [us]: pose arrival -> the servo's write, that write -> sent (p50, p99).
  double to_servo_p50_us = 0, to_servo_p99_us = 0, to_send_p50_us = 0, to_send_p99_us = 0;
  /// How late the stream's poses ran behind their predicted arrival at the end [us], the 99.5th
  /// percentile of the last 256: the servo's ticks lead the arrivals by at least this + 25 us.
  double stream_late_us = 0;
  /// Servo ticks that waited past their deadline for a pose that ran later than the lead.
  long input_waits = 0;
  long input_wait_timeouts = 0;  ///< of those, the waits the pose did not end (half a period past the deadline)
  /// Poses no reply answered (between two answered: StreamReplies::passed_over), and of
  /// them those the servo never read (TransformDevice::overtaken, counted over the whole run).
  long passed_over = 0, overtaken = 0;
  long replies_dropped = 0;  ///< replies dropped, the connection kept (StreamReplies::dropped)
  /// The poses never read, by how soon the next came (TransformDevice::overtaken_gaps).
  std::array<long, 5> overtaken_gaps{};
};
/// As serve(), filling `stats` at the end.
int serve(const io::Scene& scene, const ServeOptions& options, std::ostream& log, ServeStats& stats);

}  // namespace isotouch::service
