// Runs the servo_control firmware (the real ELF) in simavr as an ATmega328P at 16 MHz:
// its UART on a pseudo-terminal (so serial_node or a test talks to it as to a USB
// serial port), every edge on PB0..PB3 (pins 8..11) and every UART byte written to an
// event file with the simulated cycle count, and simulated time paced to wall time.
//
//   servo_sim FIRMWARE.elf --pty-link /tmp/x/tty --events /tmp/x/events.txt [--clock-ppm PPM]
//
// --clock-ppm: the board's clock runs PPM parts per million fast (negative: slow) of
// 16 MHz against wall time. An Uno's ceramic resonator is within +-0.5 % (5000 ppm),
// so a host sending at 50 Hz meets the firmware's 20 ms servo frame at a phase that
// sweeps the whole frame every few seconds; paced exactly (the default, 0), the phase
// stays where the run happened to start it.
//
// Event lines:  e CYCLE PIN LEVEL   (pin 0..3 = PB0..PB3)
//               r CYCLE BYTE        (byte delivered to the AVR's UART, host -> AVR)
//               t CYCLE BYTE        (byte sent by the AVR)
//               w CYCLE NS          (bytes were read from the pty at CLOCK_REALTIME NS;
//                                    their r lines follow: ties simulated to wall time)
//               u CYCLE 0|1         (the USB cable pulled / plugged back, SIGUSR1)
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
  fprintf(stderr, "usage: servo_sim FIRMWARE.elf --pty-link PATH --events PATH [--no-realtime] [--clock-ppm PPM]\n");
  exit(2);
}

int main(int argc, char **argv) {
  const char *elf = NULL, *link_path = NULL, *events_path = NULL;
  int realtime = 1;
  double clock_ppm = 0.0;
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "--pty-link") && i + 1 < argc) link_path = argv[++i];
    else if (!strcmp(argv[i], "--events") && i + 1 < argc) events_path = argv[++i];
    else if (!strcmp(argv[i], "--no-realtime")) realtime = 0;
    else if (!strcmp(argv[i], "--clock-ppm") && i + 1 < argc) {
      char *end;
      clock_ppm = strtod(argv[++i], &end);
      if (*end || clock_ppm <= -1e6) usage();
    }
    else if (argv[i][0] != '-' && !elf) elf = argv[i];
    else usage();
  }
  if (!elf || !link_path || !events_path) usage();

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

  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signal(SIGUSR1, on_usr1);
  signal(SIGPIPE, SIG_IGN);
  fprintf(stderr, "servo_sim: %s running\n", elf);

  uint8_t pending[256];
  size_t npending = 0, next = 0;
  uint64_t t0 = now_ns();
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
    static unsigned flushes;
    if ((++flushes & 63) == 0) fflush(events);
  }
  fflush(events);
  fclose(events);
  if (master >= 0) unplug(link_path);
  return exit_code;
}
