// Runs the servo_control firmware (the real ELF) in simavr as an ATmega328P at 16 MHz:
// its UART on a pseudo-terminal (so serial_node or a test talks to it as to a USB
// serial port), every edge on PB0..PB3 (pins 8..11) and every UART byte written to an
// event file with the simulated cycle count, and simulated time paced to wall time.
//
//   servo_sim FIRMWARE.elf --pty-link /tmp/x/tty --events /tmp/x/events.txt [--clock-ppm PPM]
//             [--adc-file FILE]
//
// --clock-ppm: the board's clock runs PPM parts per million fast (negative: slow) of
// 16 MHz against wall time. An Uno's ceramic resonator is within +-0.5 % (5000 ppm),
// so a host sending at 50 Hz meets the firmware's 20 ms servo frame at a phase that
// sweeps the whole frame every few seconds; paced exactly (the default, 0), the phase
// stays where the run happened to start it.
//
// --adc-file: the leader role's inputs, a recorded hand motion: lines
//   T_MS MV0 MV1 MV2 MV3 DEADMAN
// (simulated milliseconds since power-up, non-decreasing; millivolts on A0..A3, 0..5000;
// DEADMAN 1: the button held, D2 pulled to GND, 0: released, D2 high), '#' comments.
// Voltages are interpolated linearly between two lines (two lines at the same time: a
// step), held before the first and after the last; the deadman follows the last line
// at or before the time (steps). Each channel's voltage is set when the AVR starts a
// conversion (simavr's ADC trigger), as a real ADC samples at the conversion's start;
// D2 changes at its line's cycle. AVcc = AREF = VCC = 5000 mV. Without the option the
// inputs stay at 0 mV and D2 is not driven.
//
// Event lines:  e CYCLE PIN LEVEL   (pin 0..3 = PB0..PB3)
//               r CYCLE BYTE        (byte delivered to the AVR's UART, host -> AVR)
//               t CYCLE BYTE        (byte sent by the AVR)
//               w CYCLE NS          (bytes were read from the pty at CLOCK_REALTIME NS;
//                                    their r lines follow: ties simulated to wall time)
//               u CYCLE 0|1         (the USB cable pulled / plugged back, SIGUSR1)
//               a CYCLE CH MV       (--adc-file: a conversion of channel CH started with
//                                    MV millivolts on it)
//               d CYCLE LEVEL       (--adc-file: D2 driven to LEVEL, 0 = deadman held)
//               c CYCLE             (the simulated clock, every simulated millisecond,
//                                    with the file flushed up to it: a reader knows how
//                                    far the board has run even when nothing happens,
//                                    and every byte the AVR sent before CYCLE is in the
//                                    pty; a test judges on this clock, not the wall's)
// SIGUSR1 pulls the USB cable (the pty is closed and its link removed; the AVR runs on,
// holding its pulses as a board on its own supply does) or plugs it back (a new pty at
// the same link). Stops on SIGINT/SIGTERM with exit code 0.
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <avr_adc.h>
#include <avr_ioport.h>
#include <avr_uart.h>
#include <sim_avr.h>
#include <sim_elf.h>
#include <sim_irq.h>

static volatile sig_atomic_t stop;
static volatile sig_atomic_t replug;
static FILE *events;
static avr_t *avr;
static int master = -1;
static int xoff;
static uint32_t pin_level[4] = {2, 2, 2, 2};

// --adc-file: the recorded inputs
#define AVCC_MV 5000
#define CLOCK_LINE_CYCLES 16000  // a `c` line every simulated millisecond
struct adc_point {
  double t_ms;
  double mv[4];
  int deadman;
};
static struct adc_point *adc_points;
static size_t adc_count;
static avr_irq_t *d2_irq;

static int load_adc_file(const char *path) {
  FILE *f = fopen(path, "r");
  if (!f) {
    perror("servo_sim: --adc-file");
    return -1;
  }
  char line[512];
  size_t cap = 0, lineno = 0;
  while (fgets(line, sizeof(line), f)) {
    lineno++;
    char *hash = strchr(line, '#');
    if (hash) *hash = 0;
    struct adc_point p;
    char extra;
    int n = sscanf(line, "%lf %lf %lf %lf %lf %d %c", &p.t_ms, &p.mv[0], &p.mv[1], &p.mv[2], &p.mv[3], &p.deadman, &extra);
    if (n <= 0) continue;  // blank
    if (n != 6 || p.t_ms < 0 || (adc_count && p.t_ms < adc_points[adc_count - 1].t_ms) || (p.deadman & ~1)) {
      fprintf(stderr, "servo_sim: %s:%zu: want `T_MS MV0 MV1 MV2 MV3 DEADMAN`, times non-decreasing\n", path, lineno);
      fclose(f);
      return -1;
    }
    for (int c = 0; c < 4; c++) p.mv[c] = p.mv[c] < 0 ? 0 : p.mv[c] > AVCC_MV ? AVCC_MV : p.mv[c];
    if (adc_count == cap) {
      cap = cap ? 2 * cap : 64;
      adc_points = realloc(adc_points, cap * sizeof(*adc_points));
      if (!adc_points) abort();
    }
    adc_points[adc_count++] = p;
  }
  fclose(f);
  if (!adc_count) {
    fprintf(stderr, "servo_sim: %s: no lines\n", path);
    return -1;
  }
  return 0;
}

static double cycle_ms(avr_cycle_count_t cycle) {
  return (double)cycle * 1e3 / (double)avr->frequency;
}

// The last point at or before `t_ms` (the first if none).
static size_t adc_at(double t_ms) {
  size_t i = 0;
  while (i + 1 < adc_count && adc_points[i + 1].t_ms <= t_ms) i++;
  return i;
}

static double adc_mv(double t_ms, int ch) {
  size_t i = adc_at(t_ms);
  const struct adc_point *a = &adc_points[i];
  if (t_ms <= a->t_ms || i + 1 == adc_count) return a->mv[ch];
  const struct adc_point *b = &adc_points[i + 1];
  return a->mv[ch] + (b->mv[ch] - a->mv[ch]) * (t_ms - a->t_ms) / (b->t_ms - a->t_ms);
}

// A conversion starts: the voltages now on every channel (simavr reads them when the
// firmware reads the result, from what was raised last).
static void adc_trigger(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq, (void)param;
  union {
    avr_adc_mux_t mux;
    uint32_t v;
  } e = {.v = value};
  double t = cycle_ms(avr->cycle);
  for (int c = 0; c < 4; c++) {
    uint32_t mv = (uint32_t)(adc_mv(t, c) + 0.5);
    avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + c), mv);
    if (e.mux.kind == ADC_MUX_SINGLE && e.mux.src == (unsigned)c)
      fprintf(events, "a %llu %d %u\n", (unsigned long long)avr->cycle, c, mv);
  }
}

// D2 as the file says at this cycle: the button pulls it to GND, the pull-up (and the
// "external" level simavr gives an input pin when the firmware writes PORTD) to 5 V.
static void drive_d2(int held) {
  avr_ioport_external_t ext = {.name = 'D', .mask = 1 << 2, .value = held ? 0 : 1 << 2};
  avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('D'), &ext);
  avr_raise_irq(d2_irq, held ? 0 : 1);
}

static int d2_level = -1;  // the file's deadman now: 1 held (D2 low), -1 not driven yet

// Something else raised D2 (simavr applies the internal pull-up when the firmware writes
// PORTD, in versions without "external" levels): the button wins, from the next cycle.
static avr_cycle_count_t d2_redrive(struct avr_t *a, avr_cycle_count_t when, void *param) {
  (void)a, (void)when, (void)param;
  if (d2_level >= 0) avr_raise_irq(d2_irq, d2_level ? 0 : 1);
  return 0;
}

static void d2_raised(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq, (void)param;
  if (d2_level >= 0 && (value ? 1 : 0) != (d2_level ? 0 : 1)) avr_cycle_timer_register(avr, 1, d2_redrive, NULL);
}

static avr_cycle_count_t d2_timer(struct avr_t *a, avr_cycle_count_t when, void *param) {
  (void)a, (void)when, (void)param;
  double t = cycle_ms(avr->cycle);
  size_t i = adc_at(t);
  int held = t >= adc_points[i].t_ms ? adc_points[i].deadman : adc_points[0].deadman;
  if (held != d2_level) {
    d2_level = held;
    drive_d2(held);
    fprintf(events, "d %llu %d\n", (unsigned long long)avr->cycle, held ? 0 : 1);
  }
  // again at the next line that changes it
  for (size_t j = i + 1; j < adc_count; j++) {
    if (adc_points[j].deadman != held) {
      avr_cycle_count_t at = (avr_cycle_count_t)(adc_points[j].t_ms * 1e-3 * (double)avr->frequency + 0.5);
      return at > avr->cycle ? at : avr->cycle + 1;
    }
  }
  return 0;
}

static void on_signal(int sig) {
  (void)sig;
  stop = 1;
}

static void on_usr1(int sig) {
  (void)sig;
  replug = 1;
}

static void pin_changed(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  intptr_t pin = (intptr_t)param;
  value = value ? 1 : 0;
  if (pin_level[pin] == value) return;
  pin_level[pin] = value;
  fprintf(events, "e %llu %d %u\n", (unsigned long long)avr->cycle, (int)pin, value);
}

static void uart_out(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  (void)param;
  uint8_t b = (uint8_t)value;
  fprintf(events, "t %llu %u\n", (unsigned long long)avr->cycle, b);
  ssize_t n;
  do {
    n = write(master, &b, 1);
  } while (n < 0 && errno == EINTR);
}

static void uart_xon(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq, (void)value, (void)param;
  xoff = 0;
}

static void uart_xoff(struct avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq, (void)value, (void)param;
  xoff = 1;
}

static uint64_t now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

static uint64_t realtime_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

// The pseudo-terminal: the slave end is what a client opens; keep it open and raw
// ourselves so that nothing is echoed before a client configures it.
static int slave = -1;
static int plug(const char *link_path) {
  master = posix_openpt(O_RDWR | O_NOCTTY);
  if (master < 0 || grantpt(master) || unlockpt(master)) {
    perror("servo_sim: pty");
    return -1;
  }
  const char *slave_name = ptsname(master);
  slave = open(slave_name, O_RDWR | O_NOCTTY);
  struct termios tio;
  if (slave < 0 || tcgetattr(slave, &tio)) {
    perror("servo_sim: pty slave");
    return -1;
  }
  cfmakeraw(&tio);
  tcsetattr(slave, TCSANOW, &tio);
  fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
  unlink(link_path);
  if (symlink(slave_name, link_path)) {
    perror("servo_sim: symlink");
    return -1;
  }
  fprintf(stderr, "servo_sim: UART on %s -> %s\n", link_path, slave_name);
  return 0;
}

static void unplug(const char *link_path) {
  unlink(link_path);
  close(slave);
  close(master);
  slave = master = -1;
}

static void usage(void) {
  fprintf(stderr, "usage: servo_sim FIRMWARE.elf --pty-link PATH --events PATH [--no-realtime] [--clock-ppm PPM]"
                  " [--adc-file FILE]\n");
  exit(2);
}

int main(int argc, char **argv) {
  const char *elf = NULL, *link_path = NULL, *events_path = NULL, *adc_path = NULL;
  int realtime = 1;
  double clock_ppm = 0.0;
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "--pty-link") && i + 1 < argc) link_path = argv[++i];
    else if (!strcmp(argv[i], "--events") && i + 1 < argc) events_path = argv[++i];
    else if (!strcmp(argv[i], "--no-realtime")) realtime = 0;
    else if (!strcmp(argv[i], "--adc-file") && i + 1 < argc) adc_path = argv[++i];
    else if (!strcmp(argv[i], "--clock-ppm") && i + 1 < argc) {
      char *end;
      clock_ppm = strtod(argv[++i], &end);
      if (*end || clock_ppm <= -1e6) usage();
    }
    else if (argv[i][0] != '-' && !elf) elf = argv[i];
    else usage();
  }
  if (!elf || !link_path || !events_path) usage();
  if (adc_path && load_adc_file(adc_path)) return 2;

  elf_firmware_t fw;
  memset(&fw, 0, sizeof(fw));
  if (elf_read_firmware(elf, &fw) != 0) {
    fprintf(stderr, "servo_sim: cannot read %s\n", elf);
    return 1;
  }
  avr = avr_make_mcu_by_name("atmega328p");
  if (!avr) {
    fprintf(stderr, "servo_sim: no atmega328p core in simavr\n");
    return 1;
  }
  avr_init(avr);
  avr->frequency = 16000000;
  avr->vcc = avr->avcc = avr->aref = AVCC_MV;  // a Uno on USB: the ADC's reference is AVcc
  avr->log = 1;
  avr_load_firmware(avr, &fw);

  events = fopen(events_path, "w");
  if (!events) {
    perror("servo_sim: events file");
    return 1;
  }
  setvbuf(events, NULL, _IOFBF, 1 << 16);

  if (plug(link_path)) return 1;

  for (intptr_t pin = 0; pin < 4; pin++)
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), pin), pin_changed, (void *)pin);
  avr_irq_t *uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), uart_xon, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), uart_xoff, NULL);
  if (adc_path) {
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_OUT_TRIGGER), adc_trigger, NULL);
    d2_irq = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 2);
    avr_irq_register_notify(d2_irq, d2_raised, NULL);
    avr_cycle_timer_register(avr, 1, d2_timer, NULL);
  }

  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signal(SIGUSR1, on_usr1);
  signal(SIGPIPE, SIG_IGN);
  fprintf(stderr, "servo_sim: %s running\n", elf);

  uint8_t pending[256];
  size_t npending = 0, next = 0;
  uint64_t t0 = now_ns();
  avr_cycle_count_t next_clock = 0;
  int exit_code = 0;
  while (!stop) {
    for (int i = 0; i < 4000; i++) {
      int st = avr_run(avr);
      if (st == cpu_Done || st == cpu_Crashed) {
        fprintf(stderr, "servo_sim: the AVR stopped (state %d)\n", st);
        stop = 1;
        exit_code = 1;
        break;
      }
    }
    if (replug) {
      replug = 0;
      if (master >= 0) {
        unplug(link_path);
        npending = next = 0;
        fprintf(events, "u %llu 0\n", (unsigned long long)avr->cycle);
      } else {
        if (plug(link_path)) {
          exit_code = 1;
          break;
        }
        fprintf(events, "u %llu 1\n", (unsigned long long)avr->cycle);
      }
    }
    if (next == npending && master >= 0) {
      ssize_t n = read(master, pending, sizeof(pending));
      npending = n > 0 ? (size_t)n : 0;
      next = 0;
      if (n > 0) fprintf(events, "w %llu %llu\n", (unsigned long long)avr->cycle, (unsigned long long)realtime_ns());
    }
    while (next < npending && !xoff) {
      fprintf(events, "r %llu %u\n", (unsigned long long)avr->cycle, pending[next]);
      avr_raise_irq(uart_in, pending[next++]);
    }
    if (realtime) {
      uint64_t sim_ns = (uint64_t)((double)avr->cycle * 1e9 / ((double)avr->frequency * (1.0 + clock_ppm * 1e-6)));
      uint64_t wall_ns = now_ns() - t0;
      if (sim_ns > wall_ns + 1000000ull) usleep((useconds_t)((sim_ns - wall_ns) / 1000));
    }
    if (avr->cycle >= next_clock) {
      fprintf(events, "c %llu\n", (unsigned long long)avr->cycle);
      fflush(events);
      next_clock = avr->cycle + CLOCK_LINE_CYCLES;
    }
  }
  fprintf(events, "c %llu\n", (unsigned long long)avr->cycle);
  fclose(events);
  if (master >= 0) unplug(link_path);
  return exit_code;
}
