#include "rt_cli.hpp"

#include <CLI/CLI.hpp>

#include <ostream>

namespace nao::rt {

int parseCommandLine(int argc, const char* const* argv, CommandLine& cl, std::ostream& out, std::ostream& err) {
  RunOptions& o = cl.run;
  CLI::App app{
      "nao_rt: the NAO V6 right-arm imitation controller (docs/nao_rt.md) on the ODE-simulated arm\n"
      "(default) or on a NAO V6 through LoLA (--robot lola, docs/lola.md). It runs any model of its\n"
      "compiled-in model's, the paper's or the small configuration's architecture (--weights; --info\n"
      "says \"runs\"); toolchain/nao build --model FILE builds one for another.\n"
      "Configures everything (URDF, policy, reference, attention ring, run buffers), then runs the\n"
      "deterministic 10 Hz loop - human frame -> retarget -> snap to key pose -> policy -> command ->\n"
      "100 x 1 ms of physics - with no heap allocation, and writes the run directory (docs/nao_rt.md).",
      "nao_rt"};
  app.get_formatter()->column_width(28);
  app.add_option("--weights", o.weights_path,
                 "Policy model.bin to run instead of the compiled-in model: checked (its\n"
                 "architecture must be the compiled one), then copied into aligned memory\n"
                 "allocated at start-up (none without --weights)")
      ->type_name("FILE");
  app.add_option("--precision", o.precision,
                 "Weight precision: fp32 (the reference) or int8 (attention and FFN matrices as int8\n"
                 "with one scale per row, tokens quantised to int16 per step: docs/policy.md). Default:\n"
                 "int8 if the compiled-in model was generated with nao_codegen --precision int8 and no\n"
                 "--weights is given, else fp32. With --weights the int8 copy is made at start-up.\n"
                 "fp32-packed: fp32 with the attention and FFN matrices also copied at start-up into\n"
                 "the kernels' block order (+24 MB): the same bits as fp32, read in address order")
      ->check(CLI::IsMember({"fp32", "fp32-packed", "int8"}))
      ->type_name("P");
  app.add_option("--policy-kernel", o.policy_kernel,
                 "The policy step's SIMD kernels: sse, avx2 or avx512 (default: the best this CPU runs).\n"
                 "Every kernel gives the same bits; a kernel the CPU lacks is refused")
      ->check(CLI::IsMember({"sse", "avx2", "avx512"}))
      ->type_name("K");
  app.add_option("--urdf", o.urdf_path, "Robot description (torso + right arm); the model's joints must match it")
      ->type_name("FILE")
      ->capture_default_str();
  app.add_option("--reference", o.reference,
                 "file:PATH  a recorded human: a 10 Hz skeleton CSV (nao_toolchain triangulate --rate 10)\n"
                 "none       autonomous-mode models: a rollout from one of the model's starts (--start)\n"
                 "           or from --start-pose\n"
                 "openpose:DIR0,DIR1[,...]  live cameras: the folders OpenPose --write_json fills, one per\n"
                 "           camera in --calibration's order (they need not exist yet); the newest\n"
                 "           triangulated skeleton each tick (docs/cameras.md). Needs --seconds or --ticks")
      ->type_name("SRC");
  app.add_option("--calibration", o.calibration_path,
                 "openpose: the cameras, our calibration JSON (nao_toolchain calibration --to-json\n"
                 "converts an Anipose/OpenCV TOML)")
      ->type_name("FILE");
  app.add_option("--format", o.pose_format, "openpose: keypoint layout, body25 (default) or body25b")
      ->check(CLI::IsMember({"body25", "body25b"}))
      ->type_name("F");
  app.add_option("--fps", o.fps, "openpose: the cameras' frame rate, Hz (default 30)")
      ->type_name("F")
      ->check(CLI::Range(1e-3, 1000.0));
  app.add_option("--human-scale", o.human_scale_m,
                 "openpose: the human's arm length d_h (shoulder to hand, m; 0.2-2). Default: estimated\n"
                 "live, the median over the first 3 s with the arm seen (before that, over the frames\n"
                 "so far)")
      ->type_name("M")
      ->check(CLI::Range(0.2, 2.0));
  app.add_option("--movement", o.movement, "Movement as named in model.bin (what the reference shows, or what to roll out)")
      ->type_name("M");
  app.add_option("--start", o.start_index,
                 "none only: roll out from the model's I-th start of --movement (0-based, default 0; nao_rt\n"
                 "--info lists them), at rest, a(-1) = 0, for that start's length")
      ->type_name("I")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--start-pose", o.start_pose,
                 "none only: roll out from this pose instead, q0,q1,q2,q3,q4 (rad, joint order), for the\n"
                 "mean length of the movement's starts")
      ->type_name("Q")
      ->delimiter(',')
      ->expected(5);
  auto* ticks = app.add_option("--ticks", o.ticks,
                               "Ticks (100 ms each) to run (default: the reference's length; none: the start's\n"
                               "length). Past a reference's end no human is seen")
                    ->type_name("N")
                    ->check(CLI::PositiveNumber);
  app.add_option("--seconds", o.seconds, "Run time in seconds, rounded to whole ticks (instead of --ticks)")
      ->type_name("S")
      ->check(CLI::PositiveNumber)
      ->excludes(ticks);
  app.add_flag("--realtime", o.realtime,
               "Pace ticks on absolute 100 ms deadlines (clock_nanosleep, CLOCK_MONOTONIC), with\n"
               "SCHED_FIFO + mlockall when permitted (one warning line when not); a missed deadline\n"
               "is an overrun and the loop skips to the next grid point. Without it ticks run back\n"
               "to back with identical results. With --robot lola the robot's packets are the clock:\n"
               "only SCHED_FIFO + mlockall, taken before the LoLA I/O thread starts so it inherits them");
  app.add_option("--robot", o.robot,
                 "ode          the in-process ODE arm (deterministic)\n"
                 "lola[:PATH]  a NAO V6 (or nao_lola_sim) through LoLA's Unix socket (default\n"
                 "             /tmp/robocup): safe start (stiffness ramp, move to the start pose),\n"
                 "             the 10 Hz loop on LoLA's 12 ms packet clock, safe stop at the end, on\n"
                 "             SIGINT/SIGTERM (exit 4) or when the link is lost (exit 3)")
      ->type_name("ROBOT")
      ->capture_default_str();
  app.add_flag("--lola-answer-first{false}", o.lola.answer_after_tick,
               "LoLA: answer the packet that ends a tick at once (the new command then goes out one\n"
               "cycle later) instead of after the tick's work (docs/lola.md, timing)");
  app.add_flag("--lola-io-thread,!--lola-one-thread", o.lola.io_thread,
               "LoLA: answer the packets on a thread of their own, so a tick longer than the 12 ms\n"
               "cycle (a slower CPU: the NAO's Atom) delays no answer (docs/lola.md); or all on the\n"
               "control thread. Default in this build: " +
                   std::string(NAO_LOLA_IO_THREAD_DEFAULT ? "--lola-io-thread (the robot build)" : "--lola-one-thread"));
  app.add_flag("--lola-warm,!--lola-no-warm", o.lola_warm,
               "LoLA on one thread: in the cycle before each tick's packet, load the policy's weights\n"
               "and key/value rings into the cache, so the tick does not read them from memory\n"
               "(about 0.3 ms of idle time per tick here; default on, docs/lola.md)");
  app.add_option("--lola-io-wait-ms", o.lola.io_wait_ms,
                 "With --lola-io-thread: how long the packet that ends a tick waits for the tick's\n"
                 "command before it is answered toward the old one (default 4; 0 with\n"
                 "--lola-answer-first)")
      ->type_name("MS")
      ->check(CLI::Range(0.0, 11.0))
      ->capture_default_str();
  app.add_option("--log", o.log_dir, "Run directory (created if missing): ticks.csv, attention.bin, summary.json")
      ->type_name("DIR");
  app.add_option("--attention-shm", o.attention_shm,
                 "Put the attention ring into POSIX shared memory NAME (watch it live with\n"
                 "nao_attn_tail NAME); default: in process")
      ->type_name("NAME");
  app.add_flag("--zero-timing", o.zero_timing,
               "Write ticks.csv's timing columns (the *_us ones) as 0, so that two identical runs\n"
               "give byte-identical files");
  app.add_flag("--info", cl.info,
               "Check the model (compiled-in, or --weights) against the URDF, print it as one JSON\n"
               "object (architecture, tensor count, checksum, trained-for joints, autonomous starts per\n"
               "movement) and exit");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e, out, err);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e, out, err);
  } catch (const CLI::ParseError& e) {
    err << "nao_rt: " << oneLine(e.what()) << " (nao_rt --help lists the flags)\n";
    return 2;
  }
  return -1;
}

}  // namespace nao::rt
